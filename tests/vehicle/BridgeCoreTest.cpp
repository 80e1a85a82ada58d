#include <cpm/vehicle/BridgeCore.hpp>
#include <cpm/vehicle/FirmwareSim.hpp>
#include <cpm/vehicle/VehicleModel.hpp>
#include <cpm/vehicle/Calibration.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <algorithm>
#include <functional>

using namespace cpm::vehicle;

namespace {

constexpr uint64_t kSecond = 1'000'000'000ull;
constexpr uint8_t kId = 5;

template <class T>
cpm::SampleResult<T> fresh(T command, uint64_t created_ns, uint64_t now_ns)
{
    command.vehicle_id(kId);
    command.header().create_stamp().nanoseconds(created_ns);
    command.header().valid_after_stamp().nanoseconds(created_ns);
    return {command, now_ns - created_ns, true};
}

VehicleCommandDirect direct(double throttle, double steering)
{
    VehicleCommandDirect c;
    c.motor_throttle(throttle);
    c.steering_servo(steering);
    return c;
}

VehicleCommandSpeedCurvature speed_curvature(double speed, double curvature)
{
    VehicleCommandSpeedCurvature c;
    c.speed(speed);
    c.curvature(curvature);
    return c;
}

TrajectoryPoint point(uint64_t t_ns, double px, double py, double vx, double vy)
{
    TrajectoryPoint p;
    p.t().nanoseconds(t_ns);
    p.px(px);
    p.py(py);
    p.vx(vx);
    p.vy(vy);
    return p;
}

StatePacket moving(uint32_t tick, double speed)
{
    StatePacket p;
    p.tick = tick;
    p.speed_mm_s = int16_t(speed * 1000);
    p.battery_mv = 7900;
    return p;
}

/// The bridge core and the simulated firmware joined in-process, 50 Hz, noise-free.
struct ClosedLoop
{
    VehicleParameters params = [] {
        VehicleParameters p;
        p.imu_yaw_rate_noise = p.imu_acceleration_noise = p.ultrasonic_noise = 0;
        return p;
    }();
    FirmwareSim sim;
    BridgeCore bridge;
    uint64_t t_ns = 100 * kSecond;

    explicit ClosedLoop(Pose start) : sim(params, World{}, start, kId, 1), bridge(kId, Calibration{}, start) {}

    /// Runs for `seconds`; `inputs` gives the commands at each cycle, `each` sees the true pose.
    void run(double seconds, const std::function<CommandInputs(uint64_t)>& inputs,
             const std::function<void(uint64_t, const Pose&)>& each = {})
    {
        for (int cycle = 0; cycle < int(seconds * 50); ++cycle) {
            for (int i = 0; i < 5; ++i) sim.step();
            t_ns += 20'000'000;
            bridge.on_observation(sim.model().pose(), t_ns);
            auto out = bridge.on_state_packet(sim.make_state_packet(), t_ns, inputs(t_ns));
            auto frame = encode_frame(out.command);
            sim.receive(frame.data(), frame.size());
            if (each) each(t_ns, sim.model().pose());
        }
    }
};

}  // namespace

TEST(Controllers, HermiteInterpolationHitsThePointsAndIsEmptyOutsideThem)
{
    std::vector<TrajectoryPoint> points{point(1 * kSecond, 0, 0, 1, 0), point(2 * kSecond, 1, 0, 1, 0),
                                        point(3 * kSecond, 2, 1, 0, 1)};
    auto at = [&](uint64_t t) { return interpolate_trajectory(points, t); };
    EXPECT_FALSE(at(kSecond - 1));
    EXPECT_FALSE(at(3 * kSecond + 1));
    ASSERT_TRUE(at(2 * kSecond));
    EXPECT_NEAR(at(2 * kSecond)->x, 1.0, 1e-12);
    EXPECT_NEAR(at(3 * kSecond)->y, 1.0, 1e-12);
    auto mid = at(1'500'000'000);  // a straight segment at constant speed stays straight
    EXPECT_NEAR(mid->x, 0.5, 1e-12);
    EXPECT_NEAR(mid->y, 0.0, 1e-12);
    EXPECT_NEAR(mid->vx, 1.0, 1e-12);
    EXPECT_NEAR(mid->ax, 0.0, 1e-12);
}

TEST(Controllers, SteeringForCurvatureInvertsTheBicycleModel)
{
    Calibration c;
    EXPECT_EQ(steering_for_curvature(c, 0.0), 0.0);
    double curvature = 1.0 / 1.25;
    double angle = steering_for_curvature(c, curvature) * c.max_steering_angle;
    EXPECT_NEAR(std::tan(angle) / c.wheelbase, curvature, 1e-12);
    EXPECT_EQ(steering_for_curvature(c, 100.0), 1.0);
    EXPECT_EQ(steering_for_curvature(c, -100.0), -1.0);
}

TEST(BridgeCore, CalibrationDescribesTheSimulatedCar)
{
    // The bridge's default calibration and the simulated car's parameters are two files' worth of
    // numbers about one car: the e2e tests' tight tolerances (a commanded circle to 2.5 %) rest on them agreeing.
    const Calibration c;
    const VehicleParameters p;
    EXPECT_EQ(c.wheelbase, p.wheelbase);
    EXPECT_EQ(c.max_steering_angle, p.max_steering_angle);
    EXPECT_EQ(c.ticks_per_metre, p.ticks_per_metre);
    EXPECT_DOUBLE_EQ(c.throttle_per_speed, 1 / p.max_speed);
    // Full left at 2000 µs, full right at 1000 µs (the model's servo).
    EXPECT_EQ(c.servo_centre_us + c.servo_range_us, 2000);
    EXPECT_EQ(c.servo_centre_us - c.servo_range_us, 1000);
    VehicleModel model(p);
    EXPECT_NEAR(model.steering_for_servo(2000), p.max_steering_angle, 1e-12);
    EXPECT_NEAR(model.steering_for_servo(1000), -p.max_steering_angle, 1e-12);
}

TEST(BridgeCore, DirectBeatsSpeedCurvatureAndAStaleCommandIsIgnored)
{
    BridgeCore sut(kId, Calibration{});
    uint64_t now = 50 * kSecond;
    CommandInputs inputs;
    inputs.direct = fresh(direct(0.5, -1.0), now - 100'000'000, now);
    inputs.speed_curvature = fresh(speed_curvature(1.0, 0.5), now - 10'000'000, now);
    auto cycle = sut.on_state_packet(moving(1000, 0.5), now, inputs);
    EXPECT_EQ(cycle.active, ActiveCommand::direct);
    EXPECT_EQ(cycle.command.motor_mode, MotorMode::forward);
    EXPECT_EQ(cycle.command.motor_pwm, 500);
    EXPECT_EQ(cycle.command.servo_us, 1000);
    EXPECT_EQ(cycle.command.vehicle_id, kId);

    inputs.direct = fresh(direct(0.5, -1.0), now - kSecond, now);  // exactly 1 s old: stale
    cycle = sut.on_state_packet(moving(1020, 0.5), now, inputs);
    EXPECT_EQ(cycle.active, ActiveCommand::speed_curvature);
    EXPECT_GT(cycle.command.servo_us, 1500);  // positive curvature turns left

    inputs.speed_curvature = fresh(speed_curvature(1.0, 0.5), now - 2 * kSecond, now);
    cycle = sut.on_state_packet(moving(1040, 0.5), now, inputs);
    EXPECT_EQ(cycle.active, ActiveCommand::none);
    EXPECT_EQ(cycle.command.motor_mode, MotorMode::brake);
}

TEST(BridgeCore, StopRequestBrakesUntilANewerCommandArrives)
{
    BridgeCore sut(kId, Calibration{});
    uint64_t now = 50 * kSecond;
    CommandInputs inputs;
    inputs.direct = fresh(direct(0.5, 0.0), now - 100'000'000, now);
    inputs.stop_request_ns = now - 50'000'000;
    auto cycle = sut.on_state_packet(moving(1000, 0.5), now, inputs);
    EXPECT_EQ(cycle.active, ActiveCommand::stopped);
    EXPECT_EQ(cycle.command.motor_mode, MotorMode::brake);
    inputs.direct = fresh(direct(0.5, 0.0), now - 10'000'000, now);
    cycle = sut.on_state_packet(moving(1020, 0.5), now, inputs);
    EXPECT_EQ(cycle.active, ActiveCommand::direct);
}

TEST(BridgeCore, PublishesStateAndRangesInLabUnits)
{
    BridgeCore sut(kId, Calibration{}, {1.0, 2.0, 0.0});
    StatePacket p = moving(1000, -0.25);
    p.battery_mv = 7900;
    p.us_front_mm = 1234;
    p.us_left_mm = 20;
    p.us_right_mm = 3000;
    p.odometer_steps = 100;
    sut.on_state_packet(p, kSecond, {});
    p.tick += 1000;
    p.odometer_steps = 100 + 300;  // 0.5 m at 600 ticks per metre, in a second
    auto cycle = sut.on_state_packet(p, 2 * kSecond, {});
    EXPECT_EQ(cycle.state.vehicle_id(), kId);
    EXPECT_DOUBLE_EQ(cycle.state.speed(), -0.25);
    EXPECT_DOUBLE_EQ(cycle.state.battery_voltage(), 7.9);
    EXPECT_DOUBLE_EQ(cycle.state.odometer_distance(), 0.5);
    EXPECT_DOUBLE_EQ(cycle.state.pose().x(), 1.5);
    EXPECT_DOUBLE_EQ(cycle.state.pose().y(), 2.0);
    EXPECT_DOUBLE_EQ(cycle.ranges.front(), 1.234);
    EXPECT_DOUBLE_EQ(cycle.ranges.left(), 0.02);
    EXPECT_DOUBLE_EQ(cycle.ranges.right(), 3.0);
    EXPECT_DOUBLE_EQ(cycle.ranges.hall_distance(), 0.5);
}

TEST(BridgeCore, StampsStatesWithTheControllersMeasurementTimeNotTheirArrival)
{
    BridgeCore sut(kId, Calibration{});
    const uint64_t t0 = 1000 * kSecond;
    // Ticks every 20 ms; the transfer takes 2 ms, except one packet that waited 15 ms in a buffer.
    EXPECT_EQ(sut.on_state_packet(moving(5000, 0), t0 + 2'000'000, {}).measured_ns, t0 + 2'000'000);
    EXPECT_EQ(sut.on_state_packet(moving(5020, 0), t0 + 22'000'000, {}).measured_ns, t0 + 22'000'000);
    EXPECT_EQ(sut.on_state_packet(moving(5040, 0), t0 + 57'000'000, {}).measured_ns, t0 + 42'000'000);
    // A faster packet lowers the offset for all that follow.
    EXPECT_EQ(sut.on_state_packet(moving(5060, 0), t0 + 61'000'000, {}).measured_ns, t0 + 61'000'000);
    EXPECT_EQ(sut.on_state_packet(moving(5080, 0), t0 + 83'000'000, {}).measured_ns, t0 + 81'000'000);
    // A controller that restarted (its tick went back) starts a new mapping.
    EXPECT_EQ(sut.on_state_packet(moving(10, 0), t0 + 200'000'000, {}).measured_ns, t0 + 200'000'000);
}

TEST(BridgeCore, StatesThatWaitedInTheLineArePublishedEachAtItsTimeWithoutACommand)
{
    // Five packets read at once (the line was read 100 ms late): the first four are measured
    // states like any other, published with their own times and poses; only the newest is
    // answered with a command.
    BridgeCore sut(kId, Calibration{}, {0.0, 0.0, 0.0});
    const uint64_t t0 = 1000 * kSecond;
    StatePacket p = moving(5000, 0.5);
    p.odometer_steps = 0;
    (void)sut.on_state_packet(p, t0, {});
    const uint64_t read_at = t0 + 100'000'000;
    for (int k = 1; k <= 4; ++k) {
        p.tick = 5000 + 20 * k;
        p.odometer_steps = int32_t(6 * k);  // 1 cm per 20 ms at 600 steps per metre
        p.us_front_mm = uint16_t(1000 - k);
        const BridgeCycle late = sut.on_waiting_state_packet(p, read_at);
        EXPECT_EQ(late.measured_ns, t0 + uint64_t(k) * 20'000'000) << "packet " << k;
        EXPECT_NEAR(late.state.pose().x(), 0.01 * k, 1e-9) << "packet " << k;
        EXPECT_DOUBLE_EQ(late.state.odometer_distance(), 0.01 * k);
        EXPECT_DOUBLE_EQ(late.ranges.front(), (1000 - k) * 1e-3);
        EXPECT_EQ(late.state.vehicle_id(), kId);
    }
    p.tick = 5100;
    p.odometer_steps = 30;
    const BridgeCycle newest = sut.on_state_packet(p, read_at, {});
    EXPECT_EQ(newest.measured_ns, t0 + 100'000'000);
    EXPECT_NEAR(newest.state.pose().x(), 0.05, 1e-9);
    EXPECT_EQ(newest.command.tick, 5100u);
}

TEST(BridgeCore, SpeedControllerReachesTheCommandedSpeedInClosedLoop)
{
    ClosedLoop loop({0, 0, 0});
    loop.run(3.0, [&](uint64_t t) {
        CommandInputs in;
        in.speed_curvature = fresh(speed_curvature(1.2, 0.0), t - 5'000'000, t);
        return in;
    });
    EXPECT_NEAR(loop.sim.model().speed(), 1.2, 0.02);
    EXPECT_NEAR(loop.sim.model().pose().y, 0.0, 1e-6);
}

TEST(BridgeCore, FollowsALineThenAnArcWithinFiveCentimetres)
{
    ClosedLoop loop({0, 0, 0});
    uint64_t t0 = loop.t_ns + kSecond / 2;
    // Accelerate at 1 m/s^2 for 1 s, run straight to x = 2 m, then a left arc of radius 1 m.
    auto s_of = [](double t) { return t < 1 ? 0.5 * t * t : 0.5 + (t - 1); };
    auto v_of = [](double t) { return t < 1 ? t : 1.0; };
    std::vector<TrajectoryPoint> points;
    double end = 1.0 + 1.5 + M_PI / 2;
    for (double t = 0; t <= end + 1e-9; t += 0.1) {
        double s = s_of(t), v = v_of(t);
        uint64_t stamp = t0 + uint64_t(t * 1e9);
        if (s <= 2.0) {
            points.push_back(point(stamp, s, 0, v, 0));
        } else {
            double phi = s - 2.0;
            points.push_back(point(stamp, 2 + std::sin(phi), 1 - std::cos(phi), v * std::cos(phi), v * std::sin(phi)));
        }
    }
    VehicleCommandTrajectory trajectory;
    trajectory.trajectory_points(points);
    double worst = 0;
    loop.run(end + 0.5, [&](uint64_t t) {
        CommandInputs in;
        in.trajectory = fresh(trajectory, t - 5'000'000, t);
        return in;
    }, [&](uint64_t t, const Pose& pose) {
        if (t < t0 || t > t0 + uint64_t(end * 1e9)) return;
        double error = pose.x <= 2.0 ? std::abs(pose.y) : std::abs(std::hypot(pose.x - 2, pose.y - 1) - 1.0);
        worst = std::max(worst, error);
    });
    EXPECT_LT(worst, 0.05);
    EXPECT_NEAR(loop.sim.model().pose().x, 3.0, 0.1);
    EXPECT_NEAR(loop.sim.model().pose().y, 1.0, 0.15);
    std::printf("worst cross-track error %.1f mm\n", worst * 1000);
}

TEST(BridgeCore, PathTrackingConvergesOntoThePathAndStopsAtItsEnd)
{
    ClosedLoop loop({0, 0.3, 0});  // 30 cm off the path
    VehicleCommandPathTracking command;
    std::vector<PathPoint> path;
    for (int i = 0; i <= 40; ++i) {
        PathPoint p;
        p.pose().x(i * 0.1);
        p.s(i * 0.1);
        path.push_back(p);
    }
    command.path(path);
    command.speed(1.0);
    loop.run(8.0, [&](uint64_t t) {
        CommandInputs in;
        in.path_tracking = fresh(command, t - 5'000'000, t);
        return in;
    });
    EXPECT_NEAR(loop.sim.model().pose().y, 0.0, 0.02);
    EXPECT_NEAR(loop.sim.model().pose().x, 4.0, 0.1);
    EXPECT_NEAR(loop.sim.model().speed(), 0.0, 0.01);
}

namespace {

/// Counts the notices of one kind in a cycle.
size_t count(const BridgeCycle& cycle, Anomaly kind)
{
    return size_t(std::count_if(cycle.notices.begin(), cycle.notices.end(), [&](const Notice& n) { return n.kind == kind; }));
}

}  // namespace

TEST(BridgeCore, ANaNSpeedIsRefusedOnceAndTheNextValidCommandDrivesTheCar)
{
    BridgeCore sut(kId, Calibration{});
    uint64_t now = 50 * kSecond;
    uint32_t tick = 1000;
    CommandInputs inputs;
    inputs.speed_curvature = fresh(speed_curvature(0.5, 0.0), now - 10'000'000, now);
    for (int i = 0; i < 10; ++i, tick += 20, now += 20'000'000) {
        inputs.speed_curvature = fresh(speed_curvature(0.5, 0.0), now - 10'000'000, now);
        sut.on_state_packet(moving(tick, 0.3), now, inputs);
    }
    // One NaN command: refused, reported once though it stays the newest for several cycles.
    const uint64_t nan_created = now - 5'000'000;
    size_t refused = 0;
    for (int i = 0; i < 5; ++i, tick += 20, now += 20'000'000) {
        inputs.speed_curvature = fresh(speed_curvature(std::nan(""), 0.0), nan_created, now);
        auto cycle = sut.on_state_packet(moving(tick, 0.3), now, inputs);
        refused += count(cycle, Anomaly::refused_command);
        if (i == 0) {
            ASSERT_EQ(cycle.notices.size(), 1u);
            EXPECT_NE(cycle.notices[0].message.find("speed = nan is not a finite number"), std::string::npos)
                << cycle.notices[0].message;
        }
        EXPECT_EQ(cycle.active, ActiveCommand::none);
        EXPECT_EQ(cycle.command.motor_mode, MotorMode::brake);
        EXPECT_TRUE(std::isfinite(cycle.state.motor_throttle()));
    }
    EXPECT_EQ(refused, 1u);
    EXPECT_EQ(sut.anomalies(Anomaly::refused_command), 1u);
    // A valid command right after it is obeyed at once, with a finite, forward throttle.
    inputs.speed_curvature = fresh(speed_curvature(0.5, 0.0), now - 1'000'000, now);
    auto cycle = sut.on_state_packet(moving(tick, 0.3), now, inputs);
    EXPECT_EQ(cycle.active, ActiveCommand::speed_curvature);
    EXPECT_EQ(cycle.command.motor_mode, MotorMode::forward);
    EXPECT_GT(cycle.command.motor_pwm, 100);
    EXPECT_TRUE(std::isfinite(cycle.state.motor_throttle()));
}

TEST(BridgeCore, EveryCommandTypeRefusesNonFiniteAndOutOfRangeFieldsNamingThem)
{
    const Calibration c;
    EXPECT_EQ(command_problem(direct(0.5, -1.0), c), "");
    EXPECT_EQ(command_problem(direct(INFINITY, 0), c), "motor_throttle = inf is not a finite number");
    EXPECT_EQ(command_problem(direct(0, 1.5), c), "steering_servo = 1.5 is outside [-1, 1]");
    EXPECT_EQ(command_problem(speed_curvature(-0.3, 2.0), c), "");
    EXPECT_EQ(command_problem(speed_curvature(1e300, 0), c), "speed = 1e+300 is outside [-3, 3]");
    EXPECT_EQ(command_problem(speed_curvature(0.5, -INFINITY), c), "curvature = -inf is not a finite number");
    VehicleCommandTrajectory trajectory;
    trajectory.trajectory_points({point(kSecond, 0, 0, 1, 0), point(2 * kSecond, 1, std::nan(""), 1, 0)});
    EXPECT_EQ(command_problem(trajectory, c), "trajectory_points[1].py = nan is not a finite number");
    VehicleCommandPathTracking path;
    path.path(std::vector<PathPoint>(3));
    path.speed(0.5);
    EXPECT_EQ(command_problem(path, c), "");
    path.path()[2].pose().yaw(std::nan(""));
    EXPECT_EQ(command_problem(path, c), "path[2].pose.yaw = nan is not a finite number");
    path.path()[2].pose().yaw(0);
    path.speed(-INFINITY);
    EXPECT_EQ(command_problem(path, c), "speed = -inf is not a finite number");

    // A refused higher-priority command leaves the car to the next fresh one.
    BridgeCore sut(kId, c);
    uint64_t now = 50 * kSecond;
    CommandInputs inputs;
    inputs.direct = fresh(direct(std::nan(""), 0), now - 1'000'000, now);
    inputs.speed_curvature = fresh(speed_curvature(0.5, 0.0), now - 10'000'000, now);
    auto cycle = sut.on_state_packet(moving(1000, 0.0), now, inputs);
    EXPECT_EQ(cycle.active, ActiveCommand::speed_curvature);
    ASSERT_EQ(count(cycle, Anomaly::refused_command), 1u);
    EXPECT_NE(cycle.notices[0].message.find("direct command"), std::string::npos) << cycle.notices[0].message;
}

TEST(BridgeCore, ANegativeSpeedReversesTheCar)
{
    ClosedLoop loop({0, 0, 0});
    loop.run(3.0, [&](uint64_t t) {
        CommandInputs in;
        in.speed_curvature = fresh(speed_curvature(-0.3, 0.0), t - 5'000'000, t);
        return in;
    });
    EXPECT_NEAR(loop.sim.model().speed(), -0.3, 0.02);
    EXPECT_LT(loop.sim.model().pose().x, -0.5);
    EXPECT_LT(loop.bridge.pose().x, -0.5);  // the estimate went backwards too
}

TEST(BridgeCore, AControllerRestartRebasesTheOdometerAndKeepsThePose)
{
    BridgeCore sut(kId, Calibration{});
    StatePacket p = moving(60'000, 0.5);
    uint64_t now = 100 * kSecond;
    for (int i = 0; i < 50; ++i, p.tick += 20, now += 20'000'000) {
        p.odometer_steps = 6000 + 6 * i;  // 1 cm per cycle
        EXPECT_TRUE(sut.on_state_packet(p, now, {}).notices.empty());
    }
    const double x_before = sut.pose().x;
    EXPECT_NEAR(x_before, 0.49, 1e-9);
    p.tick = 20;  // the controller restarted: tick and odometer begin again
    p.odometer_steps = 6;
    auto cycle = sut.on_state_packet(p, now, {});
    ASSERT_EQ(count(cycle, Anomaly::controller_restart), 1u);
    EXPECT_NE(cycle.notices[0].message.find("tick 60980 -> 20"), std::string::npos) << cycle.notices[0].message;
    EXPECT_DOUBLE_EQ(sut.pose().x, x_before);  // not moved back by the 10 m the old count stood at
    p.tick += 20;
    p.odometer_steps = 12;
    sut.on_state_packet(p, now + 20'000'000, {});
    EXPECT_NEAR(sut.pose().x, x_before + 0.01, 1e-9);
    EXPECT_EQ(sut.anomalies(Anomaly::controller_restart), 1u);
}

TEST(BridgeCore, AnOdometerJumpOfKilometresIsIgnoredAndTheCountRebased)
{
    BridgeCore sut(kId, Calibration{});
    StatePacket p = moving(1000, 0.5);
    p.odometer_steps = 0;
    sut.on_state_packet(p, kSecond, {});
    p.tick += 20;
    p.odometer_steps = 600 * 5000;  // 5 km in 20 ms
    auto cycle = sut.on_state_packet(p, kSecond + 20'000'000, {});
    ASSERT_EQ(count(cycle, Anomaly::odometer_jump), 1u);
    EXPECT_NE(cycle.notices[0].message.find("odometer jumped by 5000.00 m in 20 ms"), std::string::npos)
        << cycle.notices[0].message;
    EXPECT_DOUBLE_EQ(cycle.state.odometer_distance(), 0.0);
    EXPECT_DOUBLE_EQ(sut.pose().x, 0.0);
    p.tick += 20;
    p.odometer_steps += 6;  // an ordinary step from the new count
    cycle = sut.on_state_packet(p, kSecond + 40'000'000, {});
    EXPECT_TRUE(cycle.notices.empty());
    EXPECT_NEAR(cycle.state.odometer_distance(), 0.01, 1e-12);
}

TEST(BridgeCore, ABatteryReadingOfZeroVoltsIsNotPublished)
{
    BridgeCore sut(kId, Calibration{});
    StatePacket p = moving(1000, 0.0);
    p.battery_mv = 8100;
    EXPECT_DOUBLE_EQ(sut.on_state_packet(p, kSecond, {}).state.battery_voltage(), 8.1);
    p.tick += 20;
    p.battery_mv = 0;
    auto cycle = sut.on_state_packet(p, kSecond + 20'000'000, {});
    EXPECT_DOUBLE_EQ(cycle.state.battery_voltage(), 8.1);
    ASSERT_EQ(count(cycle, Anomaly::battery_out_of_range), 1u);
    EXPECT_NE(cycle.notices[0].message.find("battery reads 0.000 V, outside [3, 20] V"), std::string::npos)
        << cycle.notices[0].message;
}

TEST(BridgeCore, TheSpeedLoopDoesNotWindUpWhileTheControllerHoldsItsWatchdogBrake)
{
    // A line that carries no command for a while (a flood, a loose cable): the controller brakes
    // and says so in every state packet. Two seconds of that must not leave a wound-up integral
    // that sends the car off faster than commanded when the commands get through again.
    auto first_throttle_after_standing = [](uint8_t status) {
        BridgeCore sut(kId, Calibration{});
        uint64_t now = 50 * kSecond;
        CommandInputs inputs;
        uint32_t tick = 1000;
        for (int i = 0; i < 100; ++i, tick += 20, now += 20'000'000) {
            inputs.speed_curvature = fresh(speed_curvature(0.5, 0), now - 10'000'000, now);
            auto p = moving(tick, 0);
            p.status = status;
            (void)sut.on_state_packet(p, now, inputs);
        }
        inputs.speed_curvature = fresh(speed_curvature(0.5, 0), now - 10'000'000, now);
        return sut.on_state_packet(moving(tick, 0), now, inputs).command.motor_pwm;
    };
    const auto braked_by_watchdog = first_throttle_after_standing(kStatusWatchdogStop);
    const auto stuck_without_a_word = first_throttle_after_standing(0);  // a car that does not move: the integral may act
    Calibration c;
    // Feed-forward and proportional term, plus what two 20 ms cycles integrate (the last braked
    // one and the first free one).
    const double fresh_start = 0.5 * c.throttle_per_speed + c.speed_kp * 0.5 + 2 * c.speed_ki * 0.5 * 0.02;
    EXPECT_NEAR(braked_by_watchdog, fresh_start * 1000, 2);
    EXPECT_GT(stuck_without_a_word, braked_by_watchdog + 100);
}

TEST(BridgeCore, ALineThatLagsItsCommandsPausesTheSpeedFeedbackAndSaysSo)
{
    // The controller applies commands long after they were sent (a backed-up line: its echo of
    // the state tick the last applied command answered falls behind). Feedback through a second
    // of delay would overshoot and oscillate; the bridge drives feed-forward only until the
    // line catches up.
    BridgeCore sut(kId, Calibration{});
    Calibration c;
    uint64_t now = 50 * kSecond;
    CommandInputs inputs;
    uint32_t tick = 1000;
    std::vector<uint32_t> sent;  // the ticks the commands answered, in order
    auto answered_ago = [&](size_t n) { return sent.size() > n ? sent[sent.size() - 1 - n] : 0u; };
    auto cycle_with_echo = [&](uint32_t echoed, double speed) {
        inputs.speed_curvature = fresh(speed_curvature(0.5, 0), now - 10'000'000, now);
        auto p = moving(tick, speed);
        p.command_tick = echoed;
        auto out = sut.on_state_packet(p, now, inputs);
        EXPECT_EQ(out.command.tick, tick) << "a command names the state it answers";
        tick += 20, now += 20'000'000;
        sent.push_back(out.command.tick);
        return out;
    };
    BridgeCycle out;
    for (int i = 0; i < 10; ++i) out = cycle_with_echo(answered_ago(0), 0.5);  // in step: the last command applied
    EXPECT_FALSE(out.discard_queued_output);
    for (int i = 0; i < 60; ++i) out = cycle_with_echo(answered_ago(50), 0.1);  // a second behind, car slow
    EXPECT_NEAR(out.command.motor_pwm, 0.5 * c.throttle_per_speed * 1000, 1) << "feed-forward only";
    EXPECT_TRUE(out.discard_queued_output) << "what waits in the line answers states long gone";
    EXPECT_EQ(sut.anomalies(Anomaly::line_lag), 1u) << "once per lagging spell";
    // Catching up: still 9, then 5 commands (180 ms, 100 ms) behind. Feedback acting on the car
    // that far late sent it off at 0.89 m/s for 0.5 commanded after a flood of its line.
    for (size_t behind : {9u, 5u}) {
        out = cycle_with_echo(answered_ago(behind), 0.1);
        EXPECT_NEAR(out.command.motor_pwm, 0.5 * c.throttle_per_speed * 1000, 1) << behind << " behind: feed-forward still";
    }
    EXPECT_EQ(sut.anomalies(Anomaly::line_lag), 1u) << "the same spell";
    // About in step again (4 behind: a slower line's normal): feedback resumes (the car is
    // slow: more than feed-forward).
    out = cycle_with_echo(answered_ago(4), 0.1);
    EXPECT_GT(out.command.motor_pwm, 0.5 * c.throttle_per_speed * 1000 + 50);
    EXPECT_FALSE(out.discard_queued_output);
}
