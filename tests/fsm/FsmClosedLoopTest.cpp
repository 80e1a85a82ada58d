// The shipped machines driving the simulated car (FirmwareSim, its vehicle model and rangers in
// the shipped corridor) through the bridge's command path, in-process at 50 Hz, noise off.
#include <cpm/fsm/Loader.hpp>
#include "ClosedLoopCar.hpp"

#include <gtest/gtest.h>

#include <cmath>

using namespace cpm;

namespace {

struct Step
{
    vehicle::Pose pose;
    int state = 0;
    double steering = 0;
    double clearance = 0;  ///< ground truth: the right ranger's distance to the first leg's right wall (y = -0.6)
};

/// Runs the machine file for `seconds` with the car starting at (0, -0.01, 0), where the right
/// ranger is 0.5 m from the right wall.
std::vector<Step> drive(const std::string& machine_file, double seconds)
{
    auto world = vehicle::World::load(std::string(CPM_SOURCE_DIR) + "/scenarios/maps/corridor.json");
    vehicle::VehicleParameters params;
    params.imu_yaw_rate_noise = params.imu_acceleration_noise = params.ultrasonic_noise = 0;
    const vehicle::Pose start{0, -0.01, 0};
    cpm_test::ClosedLoopCar car(params, world, start);
    auto loaded = fsm::load_file(std::string(CPM_SOURCE_DIR) + "/scenarios/fsm/" + machine_file);
    EXPECT_TRUE(loaded.ok()) << (loaded.errors.empty() ? "" : loaded.errors[0].text());
    if (!loaded.ok()) return {};
    auto& machine = *loaded.machine;
    const auto& mount = params.ultrasonic[2];

    std::vector<Step> trace;
    for (int cycle = 0; cycle < int(seconds * 50); ++cycle) {
        const fsm::Inputs in = car.step();
        auto out = machine.tick(in, 0.02);
        car.command(out);

        const auto& pose = car.pose();
        const double sensor_y = pose.y + std::sin(pose.yaw) * mount.x + std::cos(pose.yaw) * mount.y;
        trace.push_back({pose, machine.active().id(), out.steering, sensor_y + 0.6});
        if (std::getenv("FSM_TRACE") && cycle % 10 == 0) {
            std::printf("t %.1f state %d pose %.2f %.3f %.2f clearance %.3f right %.3f front %.2f steer %.2f\n", cycle * 0.02,
                        machine.active().id(), pose.x, pose.y, pose.yaw, trace.back().clearance, in.right, in.front, out.steering);
        }
        if (machine.in_final_state() && std::abs(car.car().model().speed()) < 1e-3) break;
    }
    return trace;
}

}  // namespace

TEST(FsmClosedLoop, FollowsTheRightWallAtHalfAMetrePassesTheNicheTakesTheCornerAndStops)
{
    auto trace = drive("corridor.json", 40);
    ASSERT_FALSE(trace.empty());
    std::vector<int> visited{trace.front().state};
    double worst = 0, steer_straight = 0, steer_niche = 0;
    for (const auto& s : trace) {
        if (s.state != visited.back()) visited.push_back(s.state);
        if (s.state != 0 || s.pose.x < 1.0) continue;  // settled after the first metre
        worst = std::max(worst, std::abs(s.clearance - 0.5));
        (s.pose.x > 2.3 && s.pose.x < 3.6 ? steer_niche : steer_straight) =
            std::max(s.pose.x > 2.3 && s.pose.x < 3.6 ? steer_niche : steer_straight, std::abs(s.steering));
    }
    const auto& end = trace.back();
    EXPECT_EQ(visited, (std::vector<int>{0, 1, 2, 3}));
    EXPECT_LT(worst, 0.02);
    EXPECT_LT(steer_niche, 0.1);  // the door niche does not make it swerve
    // Around the corner: heading up the second leg (+y), between its walls (x = 6.4 .. 8.0),
    // stopped before its end wall (y = 5).
    EXPECT_NEAR(end.pose.yaw, M_PI / 2, 0.1);
    EXPECT_NEAR(end.pose.x, 7.41, 0.05);
    EXPECT_GT(end.pose.y, 3.8);
    EXPECT_LT(end.pose.y, 4.6);
    std::printf("first leg: clearance within %.1f mm of 0.5 m; |steering| up to %.3f on the straight, %.3f at the niche; "
                "end pose (%.2f, %.2f, %.2f)\n", worst * 1000, steer_straight, steer_niche, end.pose.x, end.pose.y, end.pose.yaw);
}

TEST(FsmClosedLoop, RampsTheClearanceFromHalfAMetreToPointEightOverTwoMetres)
{
    auto trace = drive("lane_change.json", 30);
    ASSERT_FALSE(trace.empty());
    std::vector<int> visited{trace.front().state};
    const Step* ramp_start = nullptr;
    const Step* ramp_end = nullptr;
    for (const auto& s : trace) {
        if (s.state != visited.back()) {
            visited.push_back(s.state);
            if (s.state == 1) ramp_start = &s;
            if (s.state == 2) ramp_end = &s;
        }
    }
    EXPECT_EQ(visited, (std::vector<int>{0, 1, 2, 3}));
    ASSERT_TRUE(ramp_start && ramp_end);
    EXPECT_NEAR(ramp_start->clearance, 0.5, 0.02);
    EXPECT_NEAR(ramp_end->pose.x - ramp_start->pose.x, 2.0, 0.05);
    EXPECT_NEAR(ramp_end->clearance, 0.8, 0.05);
    EXPECT_NEAR(trace.back().clearance, 0.8, 0.02);
    std::printf("ramp from x %.2f (clearance %.3f) to x %.2f (clearance %.3f); at rest %.3f\n", ramp_start->pose.x,
                ramp_start->clearance, ramp_end->pose.x, ramp_end->clearance, trace.back().clearance);
}
