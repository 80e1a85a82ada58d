// The engine driving the simulated car (FirmwareSim, its vehicle model and rangers in the
// shipped corridor) through the bridge's command path, in-process at 50 Hz.
#include <cpm/fsm/Loader.hpp>
#include <cpm/vehicle/BridgeCore.hpp>
#include <cpm/vehicle/FirmwareSim.hpp>

#include <gtest/gtest.h>

#include <cmath>

using namespace cpm;

TEST(FsmClosedLoop, FollowsTheCorridorWallPastTheNicheAndTakesTheCorner)
{
    auto world = vehicle::World::load(std::string(CPM_SOURCE_DIR) + "/scenarios/maps/corridor.json");
    vehicle::VehicleParameters params;
    params.imu_yaw_rate_noise = params.imu_acceleration_noise = params.ultrasonic_noise = 0;
    vehicle::FirmwareSim car(params, world, {0, 0.05, 0}, 1, 1);
    vehicle::BridgeCore bridge(1, vehicle::Calibration{}, {0, 0.05, 0});
    // Follow the right wall at 0.40 m; when the end wall comes within 0.9 m, turn left for 0.9 m;
    // then follow the (new) right wall again and stop when the corridor's end is 0.6 m ahead.
    auto loaded = fsm::load_json(R"({"root": 0, "tick_period": 0.02,
        "states": [{"id": 0, "type": "FollowWall", "side": "right", "clearance": 0.40, "speed": 0.5, "p": 4, "d": 3},
                   {"id": 1, "type": "Motor", "speed": 0.4, "steering": 1.0, "distance": 0.9},
                   {"id": 2, "type": "FollowWall", "side": "right", "clearance": 0.40, "speed": 0.5, "p": 4, "d": 3},
                   {"id": 3, "type": "Stop"}],
        "transitions": [{"id": 0, "type": "SensorLevel", "from": 0, "to": 1, "sensor": "front", "level": 0.9, "direction": "below", "debounce": 2},
                        {"id": 1, "type": "Finished", "from": 1, "to": 2},
                        {"id": 2, "type": "SensorLevel", "from": 2, "to": 3, "sensor": "front", "level": 0.6, "direction": "below", "debounce": 2}]})",
                                 "corridor_test.json");
    ASSERT_TRUE(loaded.ok()) << (loaded.errors.empty() ? "" : loaded.errors[0].text());
    auto& machine = *loaded.machine;

    uint64_t t_ns = 1'000'000'000;
    double worst_straight = 0, worst_niche = 0;
    std::vector<int> visited{0};
    for (int cycle = 0; cycle < 50 * 25; ++cycle) {
        for (int i = 0; i < 5; ++i) car.step();
        t_ns += 20'000'000;
        auto packet = car.make_state_packet();
        fsm::Inputs in;
        in.t = t_ns * 1e-9;
        in.odometer = packet.odometer_steps / params.ticks_per_metre;
        in.yaw = packet.imu_yaw_e4 * 1e-4;
        in.speed = packet.speed_mm_s * 1e-3;
        in.front = packet.us_front_mm * 1e-3;
        in.left = packet.us_left_mm * 1e-3;
        in.right = packet.us_right_mm * 1e-3;
        auto out = machine.tick(in, 0.02);
        if (machine.active().id() != visited.back()) visited.push_back(machine.active().id());

        vehicle::CommandInputs commands;
        VehicleCommandDirect direct;
        direct.vehicle_id(1);
        direct.motor_throttle(out.throttle);
        direct.steering_servo(out.steering);
        direct.header().create_stamp().nanoseconds(t_ns);
        commands.direct = {direct, 0, true};
        auto cycle_out = bridge.on_state_packet(packet, t_ns, commands);
        auto frame = vehicle::encode_frame(cycle_out.command);
        car.receive(frame.data(), frame.size());

        const auto& pose = car.model().pose();
        if (std::getenv("FSM_TRACE") && cycle % 10 == 0) std::printf("t %.1f state %d pose %.2f %.3f %.2f right %.3f front %.2f steer %.2f\n", cycle * 0.02, machine.active().id(), pose.x, pose.y, pose.yaw, in.right, in.front, out.steering);
        // Right sensor 9 cm right of the centre line: clearance 0.40 puts the car at y = -0.01.
        if (pose.x > 0.8 && pose.x < 1.9) worst_straight = std::max(worst_straight, std::abs(pose.y + 0.01));
        if (pose.x > 1.9 && pose.x < 3.2 && machine.active().id() == 0) worst_niche = std::max(worst_niche, std::abs(pose.y + 0.01));
    }
    const auto& pose = car.model().pose();
    EXPECT_EQ(visited, (std::vector<int>{0, 1, 2, 3}));
    EXPECT_LT(worst_straight, 0.03);
    EXPECT_LT(worst_niche, 0.05);  // the door niche does not make it swerve
    // Around the corner: heading up the second leg (+y), between its walls (x = 4.5 .. 5.5),
    // stopped before its end wall (y = 4).
    EXPECT_NEAR(pose.yaw, M_PI / 2, 0.2);
    EXPECT_GT(pose.x, 4.6);
    EXPECT_LT(pose.x, 5.4);
    EXPECT_GT(pose.y, 2.8);
    EXPECT_LT(pose.y, 3.7);
    EXPECT_NEAR(car.model().speed(), 0.0, 0.01);
    std::printf("straight %.1f mm, niche %.1f mm, end pose (%.2f, %.2f, %.2f)\n", worst_straight * 1000, worst_niche * 1000,
                pose.x, pose.y, pose.yaw);
}
