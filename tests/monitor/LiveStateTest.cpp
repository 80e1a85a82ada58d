// What cpm monitor shows, from samples given by hand: where each car is drawn, when it is stale,
// how long its FSM has been in its state, its distance to the nearest wall or car, the markers
// it sees, the rates of topics, the newest log lines, and numbers JSON cannot carry; and the
// warning for listening beyond this host.
#include <cpm/monitor/LiveState.hpp>
#include <cpm/monitor/Monitor.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

using cpm::monitor::LiveState;

namespace {

constexpr uint64_t kSecond = 1'000'000'000ull;
constexpr uint64_t kT0 = 1'000 * kSecond;

VehicleState state(uint8_t id, double x, double y, double speed, uint64_t stamp)
{
    VehicleState s;
    s.vehicle_id(id);
    s.pose().x(x);
    s.pose().y(y);
    s.pose().yaw(0.5);
    s.speed(speed);
    s.battery_voltage(8.1);
    s.header().create_stamp().nanoseconds(stamp);
    return s;
}

VehicleObservation observation(uint8_t id, double x, double y)
{
    VehicleObservation o;
    o.vehicle_id(id);
    o.pose().x(x);
    o.pose().y(y);
    o.pose().yaw(0.25);
    return o;
}

const nlohmann::json& car(const nlohmann::json& snapshot, int id)
{
    for (const auto& v : snapshot["vehicles"]) {
        if (v["id"] == id) return v;
    }
    throw std::runtime_error("no car " + std::to_string(id) + " in " + snapshot.dump());
}

/// A corridor: walls along y = -1 and y = +1.
cpm::vehicle::World corridor()
{
    return cpm::vehicle::World({{-5, -1, 5, -1}, {-5, 1, 5, 1}}, {});
}

}  // namespace

TEST(LiveState, ACarIsDrawnWhereItIsSeenAndItsPanelShowsItsOwnState)
{
    LiveState live;
    live.on_state(state(5, 1.0, 2.0, 0.4, kT0), kT0);
    auto v = car(live.snapshot(kT0 + 10'000'000), 5);
    EXPECT_DOUBLE_EQ(v["x"], 1.0);
    EXPECT_DOUBLE_EQ(v["y"], 2.0);
    EXPECT_EQ(v["pose_from"], "vehicleState") << "nothing seen from outside: where the car thinks it is";
    EXPECT_DOUBLE_EQ(v["speed"], 0.4);
    EXPECT_DOUBLE_EQ(v["battery_voltage"], 8.1);
    EXPECT_NEAR(v["age_ms"].get<double>(), 10.0, 1e-6);
    EXPECT_EQ(v["stale"], false);

    live.on_observation(observation(5, 1.1, 2.2), kT0 + 20'000'000);
    v = car(live.snapshot(kT0 + 30'000'000), 5);
    EXPECT_DOUBLE_EQ(v["x"], 1.1) << "the observation (ground truth or camera) wins while it is fresh";
    EXPECT_DOUBLE_EQ(v["y"], 2.2);
    EXPECT_DOUBLE_EQ(v["yaw"], 0.25);
    EXPECT_EQ(v["pose_from"], "vehicleObservation");
    EXPECT_DOUBLE_EQ(v["speed"], 0.4) << "speed still from the car's own state";
}

TEST(LiveState, TheCarsPanelSaysWhoPlacedIt)
{
    LiveState live;
    live.on_state(state(5, 1.0, 2.0, 0.4, kT0), kT0);
    EXPECT_EQ(car(live.snapshot(kT0), 5)["pose_source"], "its own estimate (vehicleState)");
    live.on_observation(observation(5, 1.1, 2.2), kT0);
    EXPECT_EQ(car(live.snapshot(kT0), 5)["pose_source"], "vehicleObservation") << "no writer discovered yet";
    const uint64_t before = live.version();
    live.set_observation_writers({"ips_node"});
    EXPECT_GT(live.version(), before) << "a new snapshot goes out";
    EXPECT_EQ(car(live.snapshot(kT0), 5)["pose_source"], "the positioning system (ips_node)");
    live.set_observation_writers({"firmware_sim", "firmware_sim"});
    EXPECT_EQ(car(live.snapshot(kT0), 5)["pose_source"], "the simulator's ground truth");
    live.set_observation_writers({"firmware_sim", "ips_node"});
    EXPECT_EQ(car(live.snapshot(kT0), 5)["pose_source"], "vehicleObservation from firmware_sim, ips_node")
        << "two sources on one topic: both named";
}

TEST(LiveState, ACarThatFallsSilentIsStaleNotStandingStill)
{
    LiveState live;
    live.on_state(state(3, 0, 0, 0.5, kT0), kT0);
    EXPECT_EQ(car(live.snapshot(kT0 + 900'000'000), 3)["stale"], false);
    const auto v = car(live.snapshot(kT0 + 1'500'000'000), 3);
    EXPECT_EQ(v["stale"], true);
    EXPECT_NEAR(v["age_ms"].get<double>(), 1500.0, 1e-6);
    EXPECT_DOUBLE_EQ(v["speed"], 0.5) << "its last known speed, marked stale, not 0";
    // An observation that stopped coming gives way to the car's own fresher state.
    live.on_observation(observation(3, 9, 9), kT0);
    live.on_state(state(3, 1, 1, 0.5, kT0 + 2 * kSecond), kT0 + 2 * kSecond);
    EXPECT_EQ(car(live.snapshot(kT0 + 2 * kSecond), 3)["pose_from"], "vehicleState");
}

TEST(LiveState, TheFsmStateAndHowLongItHasHeldAreOnTheLabsClock)
{
    LiveState live;
    // A replay or simulated lab: the stamps are far from this host's clock.
    const uint64_t lab = 42 * kSecond;
    live.on_state(state(7, 0, 0, 0, lab), kT0);
    FsmStatus f;
    f.vehicle_id(7);
    f.state_id(2);
    f.state_type("FollowWall");
    f.entered_ns(lab - 3 * kSecond);
    live.on_fsm(f, kT0);
    const auto v = car(live.snapshot(kT0), 7);
    EXPECT_EQ(v["fsm_state"], "FollowWall");
    EXPECT_EQ(v["fsm_state_id"], 2);
    EXPECT_NEAR(v["fsm_for_s"].get<double>(), 3.0, 1e-9);
}

TEST(LiveState, ClearanceIsToTheNearestWallOrCar)
{
    LiveState live(corridor());
    live.on_state(state(1, 0, 0.5, 0, kT0), kT0);
    auto v = car(live.snapshot(kT0), 1);
    EXPECT_NEAR(v["clearance_m"].get<double>(), 0.5, 1e-9);
    EXPECT_EQ(v["clearance_to"], "wall");
    live.on_state(state(2, 0.3, 0.5, 0, kT0), kT0);
    v = car(live.snapshot(kT0), 1);
    EXPECT_NEAR(v["clearance_m"].get<double>(), 0.3, 1e-9);
    EXPECT_EQ(v["clearance_to"], "car 2");
    // A stale car is not an obstacle any more.
    live.on_state(state(1, 0, 0.5, 0, kT0 + 3 * kSecond), kT0 + 3 * kSecond);
    v = car(live.snapshot(kT0 + 3 * kSecond), 1);
    EXPECT_EQ(v["clearance_to"], "wall");
}

TEST(LiveState, MarkersAreShownWhileFresh)
{
    LiveState live;
    live.on_state(state(4, 0, 0, 0, kT0), kT0);
    ArucoMarkers m;
    m.vehicle_id(4);
    ArucoMarker one;
    one.id(17);
    one.distance(0.8);
    one.pose().x(0.7);
    one.pose().y(0.1);
    m.markers().push_back(one);
    live.on_markers(m, kT0);
    auto v = car(live.snapshot(kT0 + 100'000'000), 4);
    ASSERT_EQ(v["markers"].size(), 1u);
    EXPECT_EQ(v["markers"][0]["id"], 17);
    EXPECT_DOUBLE_EQ(v["markers"][0]["distance"], 0.8);
    EXPECT_TRUE(car(live.snapshot(kT0 + 2 * kSecond), 4)["markers"].empty()) << "seen 2 s ago: no longer shown";
}

TEST(LiveState, NumbersJsonCannotCarryBecomeNull)
{
    LiveState live;
    auto s = state(9, std::numeric_limits<double>::quiet_NaN(), 1, std::numeric_limits<double>::infinity(), kT0);
    live.on_state(s, kT0);
    const auto snap = live.snapshot(kT0);
    const auto& v = car(snap, 9);
    EXPECT_TRUE(v["x"].is_null());
    EXPECT_TRUE(v["speed"].is_null());
    EXPECT_FALSE(nlohmann::json::parse(snap.dump(), nullptr, false).is_discarded()) << "the page can parse it";
}

TEST(LiveState, TopicsHaveRatesAndTheHistoryFillsInTheRest)
{
    LiveState live;
    for (int i = 0; i < 100; ++i) live.count("vehicleState", 1, kT0 + uint64_t(i) * 20'000'000);  // 50 Hz for 2 s
    HistoryStatus h;
    HistoryTopicStatus camera;
    camera.topic("cameraFrame");
    camera.rate_hz(15);
    h.topics().push_back(camera);
    HistoryTopicStatus state_seen_by_history;
    state_seen_by_history.topic("vehicleState");
    state_seen_by_history.rate_hz(49);
    h.topics().push_back(state_seen_by_history);
    live.on_history_status(h, kT0 + 2 * kSecond);
    const auto topics = live.snapshot(kT0 + 2 * kSecond)["topics"];
    ASSERT_EQ(topics.size(), 2u) << topics.dump();
    EXPECT_EQ(topics[0]["name"], "cameraFrame");
    EXPECT_EQ(topics[0]["from"], "history");
    EXPECT_DOUBLE_EQ(topics[0]["rate_hz"], 15);
    EXPECT_EQ(topics[1]["name"], "vehicleState");
    EXPECT_EQ(topics[1]["from"], "monitor") << "counted by the monitor itself where it reads the topic";
    EXPECT_NEAR(topics[1]["rate_hz"].get<double>(), 50, 1);
    // Nothing for 5 s: the rate falls to 0 rather than keeping its last value, and the history's
    // figures, not renewed, are no longer shown.
    const auto later = live.snapshot(kT0 + 7 * kSecond)["topics"];
    ASSERT_EQ(later.size(), 1u) << later.dump();
    EXPECT_EQ(later[0]["name"], "vehicleState");
    EXPECT_DOUBLE_EQ(later[0]["rate_hz"], 0);
}

TEST(LiveState, TheNewestLogLinesAreKeptWithTheirLevel)
{
    cpm::monitor::LiveOptions options;
    options.log_lines = 3;
    LiveState live(std::nullopt, options);
    for (int i = 0; i < 5; ++i) {
        Log l;
        l.id("node");
        l.content("line " + std::to_string(i));
        l.log_level(i == 4 ? 1 : 3);
        l.stamp().nanoseconds(kT0 + uint64_t(i));
        live.on_log(l, kT0);
    }
    const auto log = live.snapshot(kT0)["log"];
    ASSERT_EQ(log.size(), 3u);
    EXPECT_EQ(log[0]["text"], "line 2");
    EXPECT_EQ(log[2]["text"], "line 4");
    EXPECT_EQ(log[2]["level"], "error");
    EXPECT_EQ(log[1]["level"], "info");
}

TEST(LiveState, PlotsHoldTheLast30SecondsAtTenPointsASecond)
{
    LiveState live(corridor());
    for (int i = 0; i <= 40 * 50; ++i) {  // 40 s at 50 Hz
        const uint64_t t = kT0 + uint64_t(i) * 20'000'000;
        live.on_state(state(1, 0, 0.25, 0.3, t), t);
    }
    const auto plots = live.plots(kT0 + 40 * kSecond);
    ASSERT_EQ(plots["vehicles"].size(), 1u);
    const auto& points = plots["vehicles"][0]["points"];
    EXPECT_NEAR(double(points.size()), 301, 2) << "10 a second over 30 s";
    EXPECT_GE(points[0][0].get<double>(), -30.001);
    EXPECT_DOUBLE_EQ(points.back()[0], 0.0);
    EXPECT_DOUBLE_EQ(points.back()[1], 0.3);
    EXPECT_NEAR(points.back()[2].get<double>(), 0.75, 1e-9);
}

TEST(LiveState, TheVersionRisesWithEverySampleSoServersSendOnlyNews)
{
    LiveState live;
    const auto v0 = live.version();
    live.on_state(state(1, 0, 0, 0, kT0), kT0);
    EXPECT_GT(live.version(), v0);
    const auto v1 = live.version();
    live.set_source("live");
    EXPECT_EQ(live.version(), v1) << "nothing changed";
    live.set_source("replay");
    EXPECT_GT(live.version(), v1);
    EXPECT_EQ(live.snapshot(kT0)["source"], "replay");
}

TEST(MonitorBind, ListeningBeyondThisHostIsWarnedAbout)
{
    EXPECT_EQ(cpm::monitor::bind_warning("127.0.0.1", true), "");
    EXPECT_EQ(cpm::monitor::bind_warning("localhost", false), "");
    const std::string open = cpm::monitor::bind_warning("0.0.0.0", false);
    EXPECT_NE(open.find("anyone"), std::string::npos) << open;
    EXPECT_EQ(open.find("stop"), std::string::npos) << "no stop buttons, no word of them: " << open;
    const std::string with_stop = cpm::monitor::bind_warning("192.168.1.10", true);
    EXPECT_NE(with_stop.find("192.168.1.10"), std::string::npos) << with_stop;
    EXPECT_NE(with_stop.find("stop its cars"), std::string::npos) << with_stop;
}
