#include <cpm/Diagnostics.hpp>
#include <cpm/vehicle/FirmwareSim.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cpm_test/SourceDir.hpp>

using namespace cpm::vehicle;

namespace {

VehicleParameters noiseless()
{
    VehicleParameters p;
    p.imu_yaw_rate_noise = 0;
    p.imu_acceleration_noise = 0;
    p.ultrasonic_noise = 0;
    return p;
}

void run_for(VehicleModel& model, double seconds, double dt = 0.004)
{
    for (double t = 0; t < seconds - 1e-9; t += dt) model.step(dt);
}

void send(FirmwareSim& sim, const CommandPacket& command)
{
    auto frame = encode_frame(command);
    sim.receive(frame.data(), frame.size());
}

void run_for(FirmwareSim& sim, double seconds)
{
    int steps = int(std::lround(seconds * sim.parameters().physics_rate));
    for (int i = 0; i < steps; ++i) sim.step();
}

// A wall across the x axis at x = 1 m and one along y = 0.5 m.
World walls() { return World({{1.0, -5.0, 1.0, 5.0}, {-5.0, 0.5, 0.9, 0.5}}, {}); }

}  // namespace

TEST(VehicleModel, SpeedStepRespondsFirstOrderAfterTheInputDelay)
{
    VehicleParameters p = noiseless();
    VehicleModel sut(p);
    sut.command(0.0, MotorMode::forward, 500, 1500);  // half PWM: 1.5 m/s target
    run_for(sut, p.input_delay - 0.004);
    EXPECT_EQ(sut.speed(), 0.0);
    run_for(sut, 0.004 + p.speed_time_constant);
    EXPECT_NEAR(sut.speed(), 1.5 * (1 - std::exp(-1.0)), 0.03);
    run_for(sut, 10 * p.speed_time_constant);
    EXPECT_NEAR(sut.speed(), 1.5, 1e-3);
    EXPECT_NEAR(sut.pose().y, 0.0, 1e-9);
    EXPECT_NEAR(sut.pose().yaw, 0.0, 1e-9);
}

TEST(VehicleModel, BrakingStopsTheCarAndReverseDrivesBackwards)
{
    VehicleModel sut(noiseless());
    sut.command(0.0, MotorMode::reverse, 1000, 1500);
    run_for(sut, 2.0);
    EXPECT_NEAR(sut.speed(), -3.0, 0.01);
    EXPECT_LT(sut.distance(), 0);
    sut.command(sut.time(), MotorMode::brake, 0, 1500);
    run_for(sut, 0.6);
    EXPECT_NEAR(sut.speed(), 0.0, 0.01);
}

TEST(VehicleModel, TurningCircleRadiusIsWheelbaseOverTanSteeringAngle)
{
    VehicleParameters p = noiseless();
    VehicleModel sut(p);
    sut.command(0.0, MotorMode::forward, 300, 1750);  // half left: 0.2 rad
    run_for(sut, 3.0);
    double expected = p.wheelbase / std::tan(0.5 * p.max_steering_angle);
    // Over one more lap, the points lie on a circle: fit its centre as the mean.
    std::vector<std::pair<double, double>> points;
    const double dt = 0.004;
    const int steps_per_lap = int(std::lround(2 * M_PI * expected / sut.speed() / dt));
    for (int i = 0; i < steps_per_lap; ++i) {
        sut.step(dt);
        points.emplace_back(sut.pose().x, sut.pose().y);
    }
    double cx = 0, cy = 0;
    for (auto [x, y] : points) cx += x / points.size(), cy += y / points.size();
    for (auto [x, y] : points) EXPECT_NEAR(std::hypot(x - cx, y - cy), expected, 0.01 * expected);
    EXPECT_GT(sut.yaw_rate(), 0);  // servo above centre turns left
}

TEST(VehicleParameters, FileErrorsNameTheMember)
{
    EXPECT_NO_THROW(VehicleParameters::parse(R"({"wheelbase": 0.3, "ultrasonic_front": [0.3, 0, 0]})", "car.json"));
    try {
        VehicleParameters::parse(R"({"wheelbase": 0.3, "wheel_base": 1})", "car.json");
        FAIL() << "no error";
    } catch (const cpm::Error& e) {
        EXPECT_NE(std::string(e.what()).find("car.json: $.wheel_base: unknown key (did you mean 'wheelbase'?)"), std::string::npos) << e.what();
    }
    try {
        VehicleParameters::parse(R"({"max_speed": "fast"})", "car.json");
        FAIL() << "no error";
    } catch (const cpm::Error& e) {
        EXPECT_NE(std::string(e.what()).find("car.json: $.max_speed: expected a finite number, got \"fast\""), std::string::npos) << e.what();
    }
    EXPECT_THROW(VehicleParameters::parse(R"({"physics_rate": 100})", "car.json"), cpm::Error);
    // Every error at once, not the first only.
    try {
        VehicleParameters::parse(R"({"max_speed": -1, "widht": 0.1, "ultrasonic_left": [0, 0]})", "car.json");
        FAIL() << "no error";
    } catch (const cpm::FileError& e) {
        ASSERT_EQ(e.diagnostics().size(), 3u) << e.what();
        EXPECT_EQ(e.diagnostics()[0].text(), "car.json: $.max_speed: -1 is out of range [0.01, inf]");
        EXPECT_EQ(e.diagnostics()[1].text(), "car.json: $.ultrasonic_left: expected [x, y, yaw], got [0,0]");
        EXPECT_NE(e.diagnostics()[2].text().find("car.json: $.widht: unknown key (did you mean 'width'?)"), std::string::npos);
    }
}

TEST(World, MapErrorsNameTheFileAndJsonPath)
{
    auto message = [](const std::string& json) {
        try {
            World::parse(json, "map.json");
        } catch (const cpm::Error& e) {
            return std::string(e.what());
        }
        return std::string("no error");
    };
    EXPECT_EQ(message(R"({"walls": [[0,0,1,0], [1,2,3]]})"), "map.json: $.walls[1]: expected [x1, y1, x2, y2], got [1,2,3]");
    EXPECT_EQ(message(R"({"walls": [[0,0,"a",0]]})"), "map.json: $.walls[0][2]: expected a finite number, got \"a\"");
    EXPECT_EQ(message(R"({"markers": [{"id": 1, "x": 0, "y": 0}]})"), "map.json: $.markers[0]: missing \"yaw\"");
    EXPECT_EQ(message(R"({"wall": []})"), "map.json: $.wall: unknown key (did you mean 'walls'?); known: walls, markers, gates, roof_markers, floor_markers");
    EXPECT_NE(message("{").find("map.json: not valid JSON"), std::string::npos);
    // Every error of the file at once, in the order of the file.
    EXPECT_EQ(message(R"({"walls": [[0,0,0,0]], "markers": [{"id": 1, "x": 0, "y": 0, "yaw": 0, "size": -1},
                                  {"id": 2, "x": 0, "y": 0, "yaw": 0}, {"id": 2, "x": 1, "y": 0, "yaw": 0}],
                       "gates": [{"left": 2, "right": 7}]})"),
              "map.json: $.walls[0]: a wall of zero length\n"
              "map.json: $.markers[0].size: must be > 0\n"
              "map.json: $.markers[2].id: id 2 is used twice\n"
              "map.json: $.gates[0].right: no marker has id 7");
}

TEST(World, ShippedCorridorLoads)
{
    auto world = World::load(cpm_test::source_dir() + "/scenarios/maps/corridor.json");
    EXPECT_GE(world.walls().size(), 8u);
    // In the corridor at the start, the left wall is 1.0 m away, the right one 0.6 m.
    EXPECT_NEAR(world.cast_ray(0, 0, M_PI / 2, 3.0), 1.0, 1e-9);
    EXPECT_NEAR(world.cast_ray(0, 0, -M_PI / 2, 3.0), 0.6, 1e-9);
}

TEST(FirmwareSim, UltrasonicRangesToAWallAtKnownPoses)
{
    VehicleParameters p = noiseless();
    double mount = p.ultrasonic[0].x;  // front sensor, 0.30 m ahead of the rear axle
    FirmwareSim straight(p, walls(), {0, 0, 0}, 1, 1);
    EXPECT_NEAR(straight.ultrasonic_range(0), 1.0 - mount, 1e-9);
    EXPECT_NEAR(straight.ultrasonic_range(1), 0.5 - p.ultrasonic[1].y, 1e-9);
    EXPECT_NEAR(straight.make_state_packet().us_front_mm, (1.0 - mount) * 1000, 1.0);

    double a = 30 * M_PI / 180;
    FirmwareSim turned(p, walls(), {0, -2, a}, 1, 1);
    EXPECT_NEAR(turned.ultrasonic_range(0), (1.0 - mount * std::cos(a)) / std::cos(a), 1e-9);

    FirmwareSim far(p, World({{10, -1, 10, 1}}, {}), {0, 0, 0}, 1, 1);
    EXPECT_EQ(far.ultrasonic_range(0), p.ultrasonic_max_range);
    EXPECT_EQ(far.make_state_packet().us_front_mm, 3000);

    FirmwareSim touching(p, World({{0.305, -1, 0.305, 1}}, {}), {0, 0, 0}, 1, 1);
    EXPECT_EQ(touching.ultrasonic_range(0), p.ultrasonic_min_range);
}

TEST(FirmwareSim, RangersSeeOtherCars)
{
    VehicleParameters p = noiseless();
    FirmwareSim sut(p, World{}, {0, 0, 0}, 1, 1);
    EXPECT_EQ(sut.ultrasonic_range(0), p.ultrasonic_max_range);
    sut.set_other_cars({{1.5, 0, M_PI / 2}});  // broadside, 1.5 m ahead
    EXPECT_NEAR(sut.ultrasonic_range(0), 1.5 - p.width / 2 - p.ultrasonic[0].x, 1e-9);
}

TEST(FirmwareSim, OdometerCountsTicksPerMetre)
{
    VehicleParameters p = noiseless();
    FirmwareSim sut(p, World{}, {}, 4, 1);
    for (int i = 0; i < 20; ++i) {
        send(sut, {uint32_t(i), 4, MotorMode::forward, 400, 1500});
        run_for(sut, 0.1);
    }
    auto state = sut.make_state_packet();
    EXPECT_NEAR(state.odometer_steps, sut.model().distance() * p.ticks_per_metre, 1.0);
    EXPECT_NEAR(sut.model().distance(), sut.model().pose().x, 1e-9);
    EXPECT_GT(sut.model().distance(), 1.5);
    EXPECT_NEAR(state.speed_mm_s, 1200, 15);
}

TEST(FirmwareSim, WatchdogBrakesAfter250msWithoutAValidCommandAndResumes)
{
    FirmwareSim sut(noiseless(), World{}, {}, 2, 1);
    send(sut, {1, 2, MotorMode::forward, 500, 1500});
    run_for(sut, 0.24);
    EXPECT_FALSE(sut.watchdog_active());
    EXPECT_EQ(sut.model().motor_mode(), MotorMode::forward);
    run_for(sut, 0.02);
    EXPECT_TRUE(sut.watchdog_active());
    run_for(sut, 0.05);
    EXPECT_EQ(sut.model().motor_mode(), MotorMode::brake);
    EXPECT_TRUE(sut.make_state_packet().status & kStatusWatchdogStop);
    send(sut, {2, 2, MotorMode::forward, 500, 1500});
    run_for(sut, 0.05);
    EXPECT_FALSE(sut.watchdog_active());
    EXPECT_EQ(sut.model().motor_mode(), MotorMode::forward);
    EXPECT_FALSE(sut.make_state_packet().status & kStatusWatchdogStop);
    EXPECT_EQ(sut.stats().watchdog_stops, 1u);
}

TEST(FirmwareSim, BadCrcAndOtherVehiclesCommandsAreFlaggedAndIgnored)
{
    FirmwareSim sut(noiseless(), World{}, {}, 2, 1);
    auto frame = encode_frame(CommandPacket{1, 2, MotorMode::forward, 500, 1500});
    frame[4] ^= 0x10;
    sut.receive(frame.data(), frame.size());
    EXPECT_TRUE(sut.make_state_packet().status & kStatusBadCrc);
    send(sut, {2, 9, MotorMode::forward, 500, 1500});
    auto state = sut.make_state_packet();
    EXPECT_FALSE(state.status & kStatusBadCrc);
    EXPECT_TRUE(state.status & kStatusWrongVehicle);
    run_for(sut, 0.1);
    EXPECT_EQ(sut.model().motor_mode(), MotorMode::brake);
    EXPECT_EQ(sut.stats().commands, 0u);
    EXPECT_EQ(sut.stats().wrong_vehicle, 1u);
    EXPECT_EQ(sut.stats().decoder.total(), 1u);
}

TEST(FirmwareSim, ACarDrivingIntoAWallStopsAgainstItAndTheContactIsCountedOnce)
{
    FirmwareSim sut(noiseless(), walls(), {0, 0, 0}, 3, 1);
    CommandPacket full{1, 3, MotorMode::forward, 1000, 1500};
    for (int i = 0; i < 150; ++i) {  // 3 s at full throttle, commands at 50 Hz
        full.tick = uint32_t(i + 1);
        send(sut, full);
        run_for(sut, 0.02);
        // The front of the body (length - rear overhang ahead of the axle) never passes x = 1.
        ASSERT_LE(sut.model().pose().x + sut.parameters().length - sut.parameters().rear_overhang, 1.0 + 1e-9)
            << "through the wall after " << (i + 1) * 20 << " ms";
    }
    EXPECT_GT(sut.model().pose().x, 0.6);  // it got there, and stands right at the wall
    EXPECT_EQ(sut.model().speed(), 0.0);
    EXPECT_TRUE(sut.against_wall());
    EXPECT_EQ(sut.stats().wall_collisions, 1u);
    auto collisions = sut.take_collisions();
    ASSERT_EQ(collisions.size(), 1u);
    EXPECT_EQ(collisions[0].wall.x1, 1.0);
    EXPECT_TRUE(sut.take_collisions().empty());

    // Backing away and driving in again is a second contact.
    CommandPacket reverse{200, 3, MotorMode::reverse, 300, 1500};
    for (int i = 0; i < 50; ++i, ++reverse.tick) {
        send(sut, reverse);
        run_for(sut, 0.02);
    }
    EXPECT_LT(sut.model().pose().x, 0.4);
    EXPECT_FALSE(sut.against_wall());
    for (int i = 0; i < 100; ++i, ++full.tick) {
        send(sut, full);
        run_for(sut, 0.02);
    }
    EXPECT_EQ(sut.stats().wall_collisions, 2u);
}

TEST(World, SegmentsThatCrossOrTouchIntersectAndParallelOnesDoNot)
{
    EXPECT_TRUE(segments_intersect({0, 0, 2, 2}, {0, 2, 2, 0}));
    EXPECT_TRUE(segments_intersect({0, 0, 1, 0}, {1, -1, 1, 1}));  // touching at an end
    EXPECT_FALSE(segments_intersect({0, 0, 1, 0}, {0, 1, 1, 1}));
    EXPECT_FALSE(segments_intersect({0, 0, 1, 0}, {2, -1, 2, 1}));
}
