#include <cpm/fsm/FsmNode.hpp>
#include <cpm/fsm/Loader.hpp>

#include <gtest/gtest.h>

#include <cmath>

using namespace cpm::fsm;

namespace {

std::unique_ptr<Machine> machine(const std::string& json)
{
    auto result = load_json(json, "test.json");
    std::string errors;
    for (auto& d : result.errors) errors += d.text() + "\n";
    EXPECT_TRUE(result.ok()) << errors;
    return std::move(result.machine);
}

Inputs at(double t, double odometer, double right = 0.4, double front = 3.0, double left = 0.6)
{
    Inputs in;
    in.t = t;
    in.odometer = odometer;
    in.right = right;
    in.front = front;
    in.left = left;
    return in;
}

}  // namespace

TEST(FsmEngine, TicksTheActiveStateThenSwitchesOnTheFirstTransitionThatFires)
{
    auto sut = machine(R"({"root": 0,
        "states": [{"id": 0, "type": "Motor", "speed": 0.6, "steering": 0.25},
                   {"id": 1, "type": "Stop"}, {"id": 2, "type": "Idle"}],
        "transitions": [{"id": 5, "type": "Distance", "from": 0, "to": 1, "distance": 1.0},
                        {"id": 6, "type": "Always", "from": 0, "to": 2}]})");
    // Distance is checked first but has not fired; Always fires.
    auto out = sut->tick(at(0, 0), 0.0125);
    EXPECT_NEAR(out.throttle, 0.2, 1e-12);  // 0.6 m/s at 1/3 throttle per m/s
    EXPECT_EQ(out.steering, 0.25);
    EXPECT_EQ(sut->active().id(), 2);
    EXPECT_EQ(sut->last_transition(), 6);

    auto second = machine(R"({"root": 0,
        "states": [{"id": 0, "type": "Motor"}, {"id": 1, "type": "Stop"}],
        "transitions": [{"id": 5, "type": "Distance", "from": 0, "to": 1, "distance": 1.0}]})");
    second->tick(at(10, 3.0), 0.0125);  // entered at odometer 3.0
    second->tick(at(11, 3.9), 0.0125);
    EXPECT_EQ(second->active().id(), 0);
    second->tick(at(12, 4.0), 0.0125);
    EXPECT_EQ(second->active().id(), 1);
    EXPECT_EQ(second->last_transition(), 5);
    EXPECT_EQ(second->entered_t(), 12);
}

TEST(FsmEngine, BasicFollowWallIsTheOriginalPidLaw)
{
    auto sut = machine(R"({"root": 0, "tick_period": 0.0125,
        "states": [{"id": 0, "type": "BasicFollowWall", "side": "right", "clearance": 0.4, "p": 2, "i": 1, "d": 0.5}],
        "transitions": []})");
    // y = p e + esum i PID_S + d (e - eold) PID_INVS; steering = -y when following the right wall.
    sut->tick(at(0, 0, 0.40), 0.0125);                  // e = 0
    auto out = sut->tick(at(0.0125, 0.01, 0.45), 0.0125);  // e = 0.05, esum = 0.05, eold = 0
    double y = 2 * 0.05 + 0.05 * 1 * 0.0125 + 0.5 * 0.05 / 0.0125;
    EXPECT_NEAR(out.steering, -std::min(y, 1.0), 1e-12);
    out = sut->tick(at(0.025, 0.02, 0.41), 0.0125);  // e = 0.01, esum = 0.06, eold = 0.05
    y = 2 * 0.01 + 0.06 * 1 * 0.0125 + 0.5 * (0.01 - 0.05) / 0.0125;
    EXPECT_NEAR(out.steering, -std::clamp(y, -1.0, 1.0), 1e-12);
}

TEST(FsmEngine, AWallFollowerKeepsItsGainsPerSecondWhenASampleIsLost)
{
    auto sut = machine(R"({"root": 0, "tick_period": 0.0125,
        "states": [{"id": 0, "type": "BasicFollowWall", "side": "right", "clearance": 0.4, "p": 2, "i": 1, "d": 0.5}],
        "transitions": []})");
    sut->tick(at(0, 0, 0.40), 0.0125);                    // e = 0
    auto out = sut->tick(at(0.025, 0.02, 0.45), 0.025);   // one sample lost: this tick covers two periods
    // The error held for two periods counts twice in the sum; its change is spread over both.
    const double y = 2 * 0.05 + (2 * 0.05) * 1 * 0.0125 + 0.5 * 0.05 / 0.025;
    EXPECT_NEAR(out.steering, -std::min(y, 1.0), 1e-12);
    // A long gap counts as at most four periods.
    sut->tick(at(1.0, 0.5, 0.45), 1.0);
    out = sut->tick(at(2.0, 0.6, 0.50), 1.0);
    const double capped = 2 * 0.10 + (2 * 0.05 + 4 * 0.05 + 4 * 0.10) * 1 * 0.0125 + 0.5 * 0.05 / 0.05;
    EXPECT_NEAR(out.steering, -std::clamp(capped, -1.0, 1.0), 1e-12);
}

TEST(FsmEngine, FollowWallIgnoresRangeJumpsOverTwoCentimetres)
{
    const char* json = R"({"root": 0, "states": [{"id": 0, "type": "%s", "side": "right", "clearance": 0.4, "p": 2, "d": 0}], "transitions": []})";
    char text[256];
    std::snprintf(text, sizeof text, json, "FollowWall");
    auto sut = machine(text);
    std::snprintf(text, sizeof text, json, "BasicFollowWall");
    auto basic = machine(text);
    for (auto* m : {sut.get(), basic.get()}) m->tick(at(0, 0, 0.40), 0.0125);
    // A door niche: the range jumps from 0.40 to 0.65.
    EXPECT_NEAR(sut->tick(at(0.0125, 0.01, 0.65), 0.0125).steering, 0.0, 1e-12);
    EXPECT_NEAR(basic->tick(at(0.0125, 0.01, 0.65), 0.0125).steering, -0.5, 1e-12);
    // Small changes are followed, from the second reading after a jump on (the first one could
    // be half in the niche).
    EXPECT_NEAR(sut->tick(at(0.025, 0.02, 0.41), 0.0125).steering, 0.0, 1e-12);
    EXPECT_NEAR(sut->tick(at(0.0375, 0.03, 0.41), 0.0125).steering, -0.02, 1e-12);
    EXPECT_NEAR(sut->tick(at(0.05, 0.04, 0.415), 0.0125).steering, -0.03, 1e-12);
}

TEST(FsmEngine, FollowWallTakesTheWallBackAfterANicheItDriftedAcross)
{
    auto sut = machine(R"({"root": 0, "states": [{"id": 0, "type": "FollowWall", "side": "right", "clearance": 0.4, "p": 2, "d": 0}], "transitions": []})");
    sut->tick(at(0, 0, 0.40), 0.0125);
    // A niche 0.8 m long: ignored all along, its far end included.
    for (double s = 0.01; s < 0.8; s += 0.01) EXPECT_NEAR(sut->tick(at(s, s, 0.65), 0.0125).steering, 0.0, 1e-12) << s;
    // Behind it the wall is 3 cm further than before (the car drifted while blind): that is
    // the wall again, not a jump, and the follower steers back to it once two readings agree.
    EXPECT_NEAR(sut->tick(at(0.81, 0.81, 0.43), 0.0125).steering, 0.0, 1e-12);
    EXPECT_NEAR(sut->tick(at(0.82, 0.82, 0.425), 0.0125).steering, -0.05, 1e-12);
    // Right after, a jump is a jump again, and so is the reading after it.
    EXPECT_NEAR(sut->tick(at(0.83, 0.83, 0.47), 0.0125).steering, -0.05, 1e-12);
    EXPECT_NEAR(sut->tick(at(0.84, 0.84, 0.43), 0.0125).steering, -0.05, 1e-12);
    // A late sample after 0.3 m driven in one tick: 2 cm is the car's drift, followed.
    EXPECT_NEAR(sut->tick(at(1.14, 1.14, 0.445), 0.3).steering, -0.09, 1e-12);
}

TEST(FsmEngine, FollowWallNeverTakesALoneReadingAtANichesEdge)
{
    auto sut = machine(R"({"root": 0, "states": [{"id": 0, "type": "FollowWall", "side": "right", "clearance": 0.4, "p": 2, "d": 0}], "transitions": []})");
    sut->tick(at(0, 0, 0.40), 0.0125);
    for (double s = 0.01; s < 0.8; s += 0.01) sut->tick(at(s, s, 0.65), 0.0125);
    // The ranger's beam leaves the niche across its edge: one reading half in it, within the
    // 10 cm that 0.8 m blind allows, then the wall.
    EXPECT_NEAR(sut->tick(at(0.80, 0.80, 0.48), 0.0125).steering, 0.0, 1e-12);
    EXPECT_NEAR(sut->tick(at(0.81, 0.81, 0.40), 0.0125).steering, 0.0, 1e-12);
    EXPECT_NEAR(sut->tick(at(0.82, 0.82, 0.41), 0.0125).steering, -0.02, 1e-12);
}

TEST(FsmEngine, WhileBlindFollowWallMovesTheWallByTheCarsOwnTurn)
{
    auto sut = machine(R"({"root": 0, "states": [{"id": 0, "type": "FollowWall", "side": "right", "clearance": 0.4, "p": 2, "d": 0}], "transitions": []})");
    sut->tick(at(0, 0, 0.42), 0.0125);  // 2 cm too far: steers right
    EXPECT_NEAR(sut->tick(at(0.01, 0.01, 0.42), 0.0125).steering, -0.04, 1e-12);
    // Into a niche, the car turned 0.1 rad right: after 0.2 m the wall it cannot see is
    // 0.2 sin(0.1) nearer, so it steers back left.
    Inputs in = at(0.02, 0.21, 0.65);
    in.yaw = -0.1;
    EXPECT_NEAR(sut->tick(in, 0.0125).steering, -2 * (0.42 - 0.2 * std::sin(0.1) - 0.4), 1e-12);
    // Turned back to the heading of the last reading taken, it keeps that line.
    in = at(0.03, 0.31, 0.65);
    EXPECT_NEAR(sut->tick(in, 0.0125).steering, -2 * (0.42 - 0.2 * std::sin(0.1) - 0.4), 1e-12);
}

TEST(FsmEngine, SensorLevelWaitsForItsDebounceCountAndTimeoutForItsSeconds)
{
    auto sut = machine(R"({"root": 0,
        "states": [{"id": 0, "type": "Motor"}, {"id": 1, "type": "Motor"}, {"id": 2, "type": "Stop"}],
        "transitions": [{"id": 0, "type": "SensorLevel", "from": 0, "to": 1, "sensor": "front", "level": 1.0, "direction": "below", "debounce": 3},
                        {"id": 1, "type": "Timeout", "from": 1, "to": 2, "seconds": 2}]})");
    sut->tick(at(0, 0, 0.4, 0.9), 0.0125);
    sut->tick(at(0.1, 0, 0.4, 0.9), 0.0125);
    sut->tick(at(0.2, 0, 0.4, 1.5), 0.0125);  // a reading above: the count starts over
    sut->tick(at(0.3, 0, 0.4, 0.9), 0.0125);
    sut->tick(at(0.4, 0, 0.4, 0.9), 0.0125);
    EXPECT_EQ(sut->active().id(), 0);
    sut->tick(at(0.5, 0, 0.4, 0.9), 0.0125);
    EXPECT_EQ(sut->active().id(), 1);
    sut->tick(at(2.4, 0), 0.0125);
    EXPECT_EQ(sut->active().id(), 1);
    sut->tick(at(2.5, 0), 0.0125);
    EXPECT_EQ(sut->active().id(), 2);
}

TEST(FsmEngine, ArucoGateFoundHandsTheGateCentreToATargetableState)
{
    auto sut = machine(R"({"root": 0,
        "states": [{"id": 0, "type": "Motor", "speed": 0.3},
                   {"id": 1, "type": "ApproachPoint", "speed": 0.3, "tolerance": 0.05},
                   {"id": 2, "type": "Stop"}],
        "transitions": [{"id": 0, "type": "ArucoGateFound", "from": 0, "to": 1, "marker_a": 3, "marker_b": 4, "range": 2.0},
                        {"id": 1, "type": "Finished", "from": 1, "to": 2}]})");
    Inputs in = at(0, 0);
    in.markers = {{3, 2.5, 0.5, 0, 2.55}, {4, 2.5, -0.5, 0, 2.55}};  // too far
    sut->tick(in, 0.0125);
    EXPECT_EQ(sut->active().id(), 0);
    in.markers = {{3, 1.0, 0.7, 0, 1.2}, {4, 1.0, -0.1, 0, 1.0}};  // centre (1.0, 0.3)
    sut->tick(in, 0.0125);
    ASSERT_EQ(sut->active().id(), 1);
    // Approaching along x (odometer only, yaw 0): steering turns left towards y = 0.3.
    auto out = sut->tick(at(0.1, 0.0), 0.0125);
    EXPECT_GT(out.steering, 0.0);
    // At the point: finished, then Stop.
    Inputs there = at(0.2, 0.0);
    there.odometer = 0;
    there.yaw = std::atan2(0.3, 1.0);
    sut->tick(there, 0.0125);
    there.t = 0.3;
    there.odometer = std::hypot(1.0, 0.3);
    sut->tick(there, 0.0125);
    EXPECT_EQ(sut->active().id(), 2);
}

TEST(FsmEngine, ArucoGateCenterTurnsTowardsTheGateUntilItFacesItsCentre)
{
    auto sut = machine(R"({"root": 0,
        "states": [{"id": 0, "type": "ArucoGateCenter", "marker_a": 3, "marker_b": 4, "speed": 0.2, "tolerance": 0.1},
                   {"id": 1, "type": "Stop"}],
        "transitions": [{"id": 0, "type": "Finished", "from": 0, "to": 1}]})");
    Inputs in = at(0, 0);
    in.markers = {{3, 1.0, 1.2, 0, 1.56}, {4, 1.0, 0.6, 0, 1.17}};  // centre (1.0, 0.9): 42 degrees left
    auto out = sut->tick(in, 0.0125);
    EXPECT_EQ(out.steering, 1.0);  // full lock left
    EXPECT_GT(out.throttle, 0.0);
    EXPECT_EQ(sut->active().id(), 0);
    in.markers = {{3, 1.0, -0.3, 0, 1.04}, {4, 1.0, -0.9, 0, 1.35}};  // centre (1.0, -0.6): right
    out = sut->tick(in, 0.0125);
    EXPECT_EQ(out.steering, -1.0);
    EXPECT_EQ(sut->active().id(), 0);
    in.markers = {{3, 1.0, 0.3, 0, 1.04}};  // one marker only: no gate, keeps turning as it was
    out = sut->tick(in, 0.0125);
    EXPECT_EQ(out.steering, -1.0);
    EXPECT_EQ(sut->active().id(), 0);
    in.markers = {{3, 1.0, 0.35, 0, 1.06}, {4, 1.0, -0.3, 0, 1.04}};  // centre (1.0, 0.025): within 0.1 rad
    out = sut->tick(in, 0.0125);
    EXPECT_EQ(out.steering, 0.0);  // aligned: straight on
    sut->tick(in, 0.0125);
    EXPECT_EQ(sut->active().id(), 1);  // finished, then Stop
}

TEST(FsmEngine, AGateIsApproachedAlongItsLineToAPointInFrontOfItAndFollowedWhileSeen)
{
    // A gate 2 m ahead, 0.4 m to the left, turned 30° (its markers' line is not across the
    // car's way): the point 1 m in front of it is reached along the gate's line.
    auto sut = machine(R"({"root": 0,
        "states": [{"id": 0, "type": "Motor", "speed": 0.3},
                   {"id": 1, "type": "ApproachPoint", "speed": 0.3, "tolerance": 0.02, "before": 1.0, "lookahead": 0.4},
                   {"id": 2, "type": "Stop"}],
        "transitions": [{"id": 0, "type": "ArucoGateFound", "from": 0, "to": 1, "marker_a": 3, "marker_b": 4, "range": 3.0},
                        {"id": 1, "type": "Finished", "from": 1, "to": 2}]})");
    const double a = M_PI / 6;  // the way through the gate
    const double cx = 2.0, cy = 0.4, w = 0.4;
    Inputs in = at(0, 0);
    in.markers = {{3, cx - w * std::sin(a), cy + w * std::cos(a), 0, 2.0}, {4, cx + w * std::sin(a), cy - w * std::cos(a), 0, 2.0}};
    sut->tick(in, 0.02);
    ASSERT_EQ(sut->active().id(), 1);
    // The point: (2 - cos 30°, 0.4 - sin 30°) = (1.134, -0.1), the line leading up to it from the
    // lower left: standing at the origin facing +x, the car first steers hard right, onto the
    // line (aiming 0.4 m along it from where it stands), not at the point itself (-0.18).
    auto out = sut->tick(at(0.02, 0.0), 0.02);
    EXPECT_LT(out.steering, -0.8);
    // The car goes 0.755 m to its right, onto the line (x = 0, y = -0.755), then along it.
    Inputs step = at(0.04, 0.755);
    step.yaw = -M_PI / 2;
    sut->tick(step, 0.02);
    step = at(0.06, 0.755 + 1.0);
    step.yaw = a;
    out = sut->tick(step, 0.02);
    EXPECT_NEAR(out.steering, 0.0, 0.02);  // on the line, facing along it
    EXPECT_EQ(sut->active().id(), 1);      // 0.31 m short of the point
    step = at(0.08, 0.755 + 1.134 / std::cos(a));
    step.yaw = a;
    sut->tick(step, 0.02);
    sut->tick(step, 0.02);
    EXPECT_EQ(sut->active().id(), 2);  // level with the point, facing the gate: finished
}

TEST(FsmEngine, AStateEnteredAgainWithoutATargetGoesBackToItsOwnPoint)
{
    // ApproachPoint 1 is entered first with a gate as target, then again by a plain transition:
    // the second time it drives to its own point (1, 0), not to the old gate.
    auto sut = machine(R"({"root": 0,
        "states": [{"id": 0, "type": "Motor", "speed": 0.3},
                   {"id": 1, "type": "ApproachPoint", "x": 1.0, "y": 0.0, "speed": 0.3, "tolerance": 0.05},
                   {"id": 2, "type": "Motor", "speed": 0.3, "distance": 0.1}],
        "transitions": [{"id": 0, "type": "ArucoGateFound", "from": 0, "to": 1, "marker_a": 3, "marker_b": 4, "range": 3.0},
                        {"id": 1, "type": "Timeout", "from": 1, "to": 2, "seconds": 0.05},
                        {"id": 2, "type": "Finished", "from": 2, "to": 1}]})");
    Inputs in = at(0, 0);
    in.markers = {{3, 2.0, 1.4, M_PI, 2.4}, {4, 2.0, 0.6, M_PI, 2.1}};  // a gate up to the left
    sut->tick(in, 0.02);
    ASSERT_EQ(sut->active().id(), 1);
    EXPECT_GT(sut->tick(at(0.02, 0.0), 0.02).steering, 0.3);  // towards the gate: left
    sut->tick(at(0.1, 0.0), 0.02);  // timeout → Motor
    ASSERT_EQ(sut->active().id(), 2);
    sut->tick(at(0.12, 0.2), 0.02);  // Motor's 0.1 m done → back into ApproachPoint, no target
    ASSERT_EQ(sut->active().id(), 1);
    EXPECT_NEAR(sut->tick(at(0.14, 0.2), 0.02).steering, 0.0, 1e-9);  // straight ahead to (1, 0)
}

TEST(FsmEngine, TheGateDirectionComesFromTheTwoMarkersPositions)
{
    // Both markers report a facing 20° off (a single marker's facing is noisy); the target's
    // direction is the normal of the line between them, towards the car.
    auto sut = machine(R"({"root": 0,
        "states": [{"id": 0, "type": "Motor", "speed": 0.3},
                   {"id": 1, "type": "ApproachPoint", "speed": 0.3, "tolerance": 0.02, "before": 0.5},
                   {"id": 2, "type": "Stop"}],
        "transitions": [{"id": 0, "type": "ArucoGateFound", "from": 0, "to": 1, "marker_a": 3, "marker_b": 4, "range": 3.0},
                        {"id": 1, "type": "Finished", "from": 1, "to": 2}]})");
    Inputs in = at(0, 0);
    in.markers = {{3, 2.0, 0.4, M_PI - 0.35, 2.0}, {4, 2.0, -0.4, M_PI - 0.35, 2.0}};
    sut->tick(in, 0.02);
    ASSERT_EQ(sut->active().id(), 1);
    // The point 0.5 m in front of the gate is (1.5, 0): straight ahead, no steering...
    EXPECT_NEAR(sut->tick(at(0.02, 0.0), 0.02).steering, 0.0, 1e-9);
    // ...and there it finishes.
    sut->tick(at(0.04, 1.5), 0.02);
    sut->tick(at(0.06, 1.5), 0.02);
    EXPECT_EQ(sut->active().id(), 2);
}

TEST(FsmEngine, ArucoGateCenterNeverTurnsBlindAndGivesUpOutOfSight)
{
    auto sut = machine(R"({"root": 0,
        "states": [{"id": 0, "type": "ArucoGateCenter", "marker_a": 3, "marker_b": 4, "speed": 0.2, "tolerance": 0.05, "blind": 0.3},
                   {"id": 1, "type": "Stop"}],
        "transitions": [{"id": 0, "type": "Finished", "from": 0, "to": 1}]})");
    Inputs in = at(0, 0);
    in.markers = {{3, 1.0, 0.3, 0, 1.04}};  // one marker only: no gate
    EXPECT_EQ(sut->tick(in, 0.02).steering, 0.0);
    in.t = 0.2;
    sut->tick(in, 0.02);
    EXPECT_EQ(sut->active().id(), 0);
    in.t = 0.35;  // 0.35 s without the gate
    sut->tick(in, 0.02);
    sut->tick(in, 0.02);
    EXPECT_EQ(sut->active().id(), 1);
}

TEST(FsmEngine, NestedMachineFinishesWhenItReachesAFinalState)
{
    auto sut = machine(R"({"root": 0,
        "states": [{"id": 0, "type": "FSMState", "machine": {"root": 0,
                      "states": [{"id": 0, "type": "Motor"}, {"id": 1, "type": "Idle", "final": true}],
                      "transitions": [{"id": 0, "type": "Distance", "from": 0, "to": 1, "distance": 0.5}]}},
                   {"id": 1, "type": "Stop"}],
        "transitions": [{"id": 0, "type": "Finished", "from": 0, "to": 1}]})");
    EXPECT_GT(sut->tick(at(0, 0), 0.0125).throttle, 0.0);  // the nested Motor drives
    sut->tick(at(1, 0.3), 0.0125);
    EXPECT_EQ(sut->active().id(), 0);
    sut->tick(at(2, 0.5), 0.0125);  // nested: Motor -> Idle (final); outer: Finished fires
    EXPECT_EQ(sut->active().id(), 1);
}

TEST(FsmEngine, FollowWallRampIsHalfwayAtHalfTheDistanceAndFinishesAtIt)
{
    auto sut = machine(R"({"root": 0, "tick_period": 0.02,
        "states": [{"id": 0, "type": "FollowWallRamp", "side": "right", "target_clearance": 0.8, "distance": 2.0, "p": 1, "d": 0}],
        "transitions": []})");
    sut->tick(at(0, 10.0, 0.5), 0.02);  // entered 0.5 m from the wall at odometer 10
    // Halfway (1 m driven) the clearance is 0.65 m: reading 0.65 means no error, no steering.
    EXPECT_NEAR(sut->tick(at(1, 11.0, 0.65), 0.02).steering, 0.0, 1e-12);
    EXPECT_FALSE(sut->active().finished());
    // Reading 0.55 there is 0.10 m too close: with p = 1 it steers away from the right wall (+).
    EXPECT_NEAR(sut->tick(at(1.02, 11.0, 0.55), 0.02).steering, 0.10, 1e-12);
    sut->tick(at(2, 12.0, 0.8), 0.02);
    EXPECT_TRUE(sut->active().finished());
}

TEST(FsmEngine, SensorLevelFiresOnlyPastTheLevelAndDistanceExactlyAtIt)
{
    auto sut = machine(R"({"root": 0,
        "states": [{"id": 0, "type": "Motor"}, {"id": 1, "type": "Motor"}, {"id": 2, "type": "Stop"}],
        "transitions": [{"id": 0, "type": "SensorLevel", "from": 0, "to": 1, "sensor": "right", "level": 0.5, "direction": "above"},
                        {"id": 1, "type": "Distance", "from": 1, "to": 2, "distance": 0.25}]})");
    sut->tick(at(0, 0, 0.5), 0.02);  // exactly at the level: not above
    EXPECT_EQ(sut->active().id(), 0);
    sut->tick(at(0.02, 0, 0.5001), 0.02);
    EXPECT_EQ(sut->active().id(), 1);  // entered at odometer 0
    sut->tick(at(0.04, 0.2499), 0.02);
    EXPECT_EQ(sut->active().id(), 1);
    sut->tick(at(0.06, 0.25), 0.02);
    EXPECT_EQ(sut->active().id(), 2);
}

TEST(FsmNode, InputsComeFromTheCarsMessagesAndTheReportMeasuresTheFollowedWall)
{
    VehicleState state;
    state.odometer_distance(2.5);
    state.pose().yaw(0.25);
    state.speed(0.5);
    RangeSensors ranges;
    ranges.front(1.5);
    ranges.left(3.0);
    ranges.right(0.45);
    ArucoMarkers markers;
    ArucoMarker m;
    m.id(7);
    m.pose().x(1.0);
    m.distance(1.1);
    markers.markers({m});
    auto in = cpm::fsm::inputs_from(state, ranges, &markers, 12.0);
    EXPECT_EQ(in.t, 12.0);
    EXPECT_EQ(in.odometer, 2.5);
    EXPECT_EQ(in.yaw, 0.25);
    EXPECT_EQ(in.right, 0.45);
    ASSERT_EQ(in.markers.size(), 1u);
    EXPECT_EQ(in.markers[0].id, 7);
    EXPECT_TRUE(cpm::fsm::inputs_from(state, ranges, nullptr, 12.0).markers.empty());

    cpm::fsm::RunReport sut({{0, {"right", 0.5}}});
    for (int i = 0; i < 10; ++i) {
        in.odometer = 2.5 + 0.1 * i;
        in.right = i < 9 ? 0.52 : 0.9;  // one door niche
        sut.add(in, 0);
    }
    const auto text = sut.text();
    EXPECT_NE(text.find("report: driven 0.90 m, heading changed by 0 deg"), std::string::npos) << text;
    EXPECT_NE(text.find("state 0, right wall at 0.50 m, 10 ticks"), std::string::npos) << text;
    EXPECT_NE(text.find("median 0.020, 90 % 0.400, max 0.400 m"), std::string::npos) << text;
}
