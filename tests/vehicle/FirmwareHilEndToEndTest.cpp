// The car's real firmware - the ELF avr-gcc built for the ATmega2560 - running in simavr under
// firmware_hil, and the real vehicle_bridge on its pty: the checks the firmware_sim tests make,
// passed by the program that would be flashed onto a car, and the faults a car's line sees.
#include "CarHarness.hpp"

#include <cpm/vehicle/Protocol.hpp>
#include <cpm/vehicle/SerialPort.hpp>
#include <cpm/vehicle/VehicleModel.hpp>

#include <cpm/AsyncReader.hpp>

#include <RangeSensors.h>
#include <VehicleCommandDirect.h>

#include <fcntl.h>
#include <fstream>
#include <random>
#include <unistd.h>

namespace {

using namespace car_harness;

class FirmwareHilEndToEnd : public ::testing::Test
{
protected:
    cpm::Participant participant{cpm_test::isolated_options()};
};

Car avr_car(std::vector<std::string> flags = {}, bool start_bridge = true)
{
    return Car(std::move(flags), start_bridge, kId, Microcontroller::avr);
}

VehicleCommandDirect direct(double throttle, double steering)
{
    VehicleCommandDirect c;
    c.motor_throttle(throttle);
    c.steering_servo(steering);
    return c;
}

/// The host's end of the line without a bridge: frames crafted by the test, state packets read.
class Line
{
public:
    explicit Line(const std::string& device) : port_(device, 115200) {}
    void send(const cpm::vehicle::CommandPacket& c)
    {
        auto frame = cpm::vehicle::encode_frame(c);
        ASSERT_TRUE(port_.write_all(frame.data(), frame.size()));
        last_sent_tick_ = c.tick;
    }
    void send_raw(const std::vector<uint8_t>& bytes) { ASSERT_TRUE(port_.write_all(bytes.data(), bytes.size())); }
    /// The state packets that arrive within `ms`.
    std::vector<cpm::vehicle::StatePacket> states_for(int ms)
    {
        std::vector<cpm::vehicle::StatePacket> out;
        const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(ms);
        uint8_t buffer[256];
        while (std::chrono::steady_clock::now() < until) {
            const long n = port_.read_some(buffer, sizeof buffer, 5);
            for (long i = 0; i < n; ++i) {
                if (auto p = decoder_.push(buffer[i])) {
                    if (auto* s = std::get_if<cpm::vehicle::StatePacket>(&*p)) out.push_back(*s);
                }
            }
        }
        if (!out.empty()) newest_tick_ = out.back().tick;
        return out;
    }
    /// The tick of the newest state packet read (0 before the first).
    uint32_t newest_tick() const { return newest_tick_; }
    /// The tick the last command sent answered.
    uint32_t last_sent_tick() const { return last_sent_tick_; }
    /// Sends `c` every 20 ms for `ms`, each answering the newest state packet (as a bridge
    /// does; with `answer_newest` false, c.tick as given), and returns the state packets
    /// meanwhile and in the 60 ms after the last (so the last packet reports what the chip made
    /// of the last command).
    std::vector<cpm::vehicle::StatePacket> command_for(cpm::vehicle::CommandPacket c, int ms, bool answer_newest = true)
    {
        std::vector<cpm::vehicle::StatePacket> out = states_for(newest_tick_ ? 20 : 200);
        for (int t = 0; t < ms; t += 20) {
            if (answer_newest) c.tick = newest_tick_;
            send(c);
            auto s = states_for(20);
            out.insert(out.end(), s.begin(), s.end());
        }
        auto s = states_for(60);
        out.insert(out.end(), s.begin(), s.end());
        return out;
    }

private:
    cpm::vehicle::SerialPort port_;
    cpm::vehicle::FrameDecoder decoder_;
    uint32_t newest_tick_ = 0;
    uint32_t last_sent_tick_ = 0;
};

size_t with_status(const std::vector<cpm::vehicle::StatePacket>& states, uint8_t bit)
{
    size_t n = 0;
    for (const auto& s : states) n += (s.status & bit) != 0;
    return n;
}

}  // namespace

TEST_F(FirmwareHilEndToEnd, SpeedCurvatureCommandDrivesACircleOfTheCommandedRadius)
{
    Watcher watch(participant);
    Car car = avr_car();
    ASSERT_TRUE(watch.wait_for_states(5)) << car.sim->errors() << car.bridge->errors();
    Repeater<VehicleCommandSpeedCurvature> command(participant, "vehicleCommandSpeedCurvature", speed_curvature(1.0, 1 / 0.8));
    std::this_thread::sleep_for(1500ms);  // let speed and steering settle
    const uint64_t t0 = cpm::get_time_ns();
    std::this_thread::sleep_for(3s);
    auto points = watch.observations_between(t0, cpm::get_time_ns());
    ASSERT_GT(points.size(), 100u);
    // The speed the bridge controls is the firmware's, measured between hall edges; the
    // steering, its servo pulse in 0.5 us steps.
    EXPECT_NEAR(fitted_radius(points), 0.8, 0.02);
    EXPECT_NEAR(mean_speed(points), 1.0, 0.03);
    std::printf("commanded circle (AVR firmware): radius %.4f m (0.8), speed %.4f m/s (1.0)\n", fitted_radius(points),
                mean_speed(points));
}

TEST_F(FirmwareHilEndToEnd, DirectCommandsReachTheMotorPinsForwardAndReverse)
{
    Watcher watch(participant);
    Car car = avr_car({"--trace-pwm"});
    ASSERT_TRUE(watch.wait_for_states(5)) << car.sim->errors() << car.bridge->errors();
    const uint64_t t0 = cpm::get_time_ns();
    auto has = [&](int mode, int pwm) {
        std::istringstream in(car.sim->output());
        for (std::string word; in >> word;) {
            unsigned long long t = 0;
            int m = -1, p = -1;
            if (word == "pwm" && (in >> t >> m >> p) && t > t0 && m == mode && p == pwm) return true;
        }
        return false;
    };
    {
        Repeater<VehicleCommandDirect> forward(participant, "vehicleCommandDirect", direct(0.35, 0));
        EXPECT_TRUE(cpm_test::wait_until([&] { return has(1, 350); }, 5s)) << car.sim->output();
    }
    {
        Repeater<VehicleCommandDirect> reverse(participant, "vehicleCommandDirect", direct(-0.2, 0));
        EXPECT_TRUE(cpm_test::wait_until([&] { return has(2, 200); }, 5s)) << car.sim->output();
    }
    // And the car moved backwards at the end: the model felt the reverse pins.
    ASSERT_TRUE(cpm_test::wait_until([&] {
        auto s = watch.states();
        return !s.empty() && s.back().speed() < -0.05;
    }, 3s));
}

TEST_F(FirmwareHilEndToEnd, KillingTheBridgeLetsTheFirmwaresWatchdogBrakeWithin250ms)
{
    Watcher watch(participant);
    Car car = avr_car({"--trace-pwm"});
    Repeater<VehicleCommandSpeedCurvature> command(participant, "vehicleCommandSpeedCurvature", speed_curvature(0.5, 0));
    ASSERT_TRUE(cpm_test::wait_until([&] { return !car.pwm_trace_after(0).empty() && car.pwm_trace_after(0).back().second == 1; }, 10s))
        << car.sim->output() << car.bridge->errors();
    std::this_thread::sleep_for(500ms);
    const uint64_t killed = cpm::get_time_ns();
    car.bridge->kill(SIGKILL);
    // The bridge's own words too: a watchdog's brake before the kill (seen once under load) is its silence.
    ASSERT_TRUE(cpm_test::wait_until([&] { return !car.pwm_trace_after(killed, 0).empty(); }, 3s))
        << "killed at " << killed << "\n" << car.sim->output() << car.sim->errors() << "the bridge:\n" << car.bridge->errors();
    const double after = double(car.pwm_trace_after(killed, 0).front().first - killed) * 1e-9;
    // 250 ms after the last command, which came up to one state period (20 ms) before the kill;
    // the outputs are sampled every 250 us of chip time.
    EXPECT_GT(after, 0.2);
    EXPECT_LT(after, 0.3);
    // The count is of the state packets that newly report the brake: the next one goes out
    // within 20 ms of it.
    std::this_thread::sleep_for(100ms);
    car.sim->kill(SIGTERM);
    ASSERT_EQ(car.sim->wait(5s), 0);
    // Stopped once while it drove, at the kill; the firmware's watchdog also stops a standing
    // car whose bridge takes over 250 ms to start (seen with a busy loop beside).
    EXPECT_GE(last_json_line(car.sim->output()).at("watchdog_stops").get<int>(), 1) << car.sim->output();
    EXPECT_EQ(car.stops_while_driving(), 1) << car.sim->output();
    std::printf("firmware's watchdog braked %.0f ms after the bridge was killed\n", after * 1000);
}

TEST_F(FirmwareHilEndToEnd, CorruptBytesOnTheLineAreSurvivedBothWays)
{
    Watcher watch(participant);
    Car car = avr_car({"--corrupt-rate", "0.2"});  // one state frame in five corrupted on its way to the bridge
    ASSERT_TRUE(watch.wait_for_states(5)) << car.bridge->errors();
    Repeater<VehicleCommandSpeedCurvature> command(participant, "vehicleCommandSpeedCurvature", speed_curvature(0.5, 0));
    write_garbage_bursts(car.device);  // towards the microcontroller, between the bridge's commands
    expect_driving_through_corruption(watch);

    car.bridge->kill(SIGTERM);
    car.sim->kill(SIGTERM);
    ASSERT_EQ(car.bridge->wait(5s), 0);
    ASSERT_EQ(car.sim->wait(5s), 0);
    const auto bridge_stats = last_json_line(car.bridge->output());
    const auto hil_stats = last_json_line(car.sim->output());
    EXPECT_GT(bridge_stats.at("decoder_errors").get<int>(), 0) << bridge_stats;
    EXPECT_GT(hil_stats.at("corrupted_frames").get<int>(), 0) << hil_stats;
    // The firmware said it threw frames away (the bad-CRC bit of its state packets).
    EXPECT_GT(hil_stats.at("bad_frames_reported").get<int>(), 0) << hil_stats;
}

TEST_F(FirmwareHilEndToEnd, AFloodOfBytesNeverLocksTheFirmwareUp)
{
    Watcher watch(participant);
    Car car = avr_car();
    ASSERT_TRUE(watch.wait_for_states(5)) << car.bridge->errors();
    Repeater<VehicleCommandSpeedCurvature> command(participant, "vehicleCommandSpeedCurvature", speed_curvature(0.5, 0));
    // Two seconds of bytes as fast as the pty takes them, zeros among them, beside the bridge.
    int line = ::open(car.device.c_str(), O_WRONLY | O_NOCTTY | O_NONBLOCK);
    ASSERT_GE(line, 0);
    std::mt19937 rng(11);
    const uint64_t flood_start = cpm::get_time_ns();
    size_t flooded = 0;
    while (cpm::get_time_ns() < flood_start + 2 * kSecond) {
        uint8_t junk[512];
        for (auto& b : junk) b = uint8_t(rng() % 8 == 0 ? 0 : rng());
        const auto n = ::write(line, junk, sizeof junk);
        if (n > 0) flooded += size_t(n);
        std::this_thread::sleep_for(1ms);
    }
    ::close(line);
    const uint64_t flood_end = cpm::get_time_ns();
    // The chip went on sending its state packets through the flood (the bridge publishes each).
    size_t during = watch.states_created_after(flood_start) - watch.states_created_after(flood_end);
    EXPECT_GT(during, 50u) << flooded << " bytes flooded; gaps: " << watch.state_gaps_between(flood_start, flood_end)
                           << "\nbridge:\n" << car.bridge->errors() << "firmware_hil:\n" << car.sim->errors();
    // And drives again once the line is quiet. The commands that waited in the line's backlog
    // answer states long gone: the bridge drops what waits in the line while it lags (left
    // there, the pty held 4-5 s of bytes the chip could not take at 115200 baud; dropped,
    // the car drove again after 1.3-1.4 s), and the firmware ignores what still gets through
    // (applied, each drove the car for 250 ms on a throttle meant for a standing car: up to
    // 0.89 m/s for 0.5 commanded on a loaded machine). Once fresh ones get through, the car does
    // not run off faster than commanded either (the bridge's speed loop did not wind up while
    // the firmware reported its watchdog's brake).
    auto driving_at = [&](uint64_t t) {
        auto window = watch.observations_between(t - kSecond / 4, t);
        return window.size() > 5 && mean_speed(window) > 0.4;
    };
    ASSERT_TRUE(cpm_test::wait_until([&] { return driving_at(cpm::get_time_ns()); }, 15s))
        << "bridge:\n" << car.bridge->errors() << "firmware_hil:\n" << car.sim->errors();
    const double back_after = double(cpm::get_time_ns() - flood_end) * 1e-9;
    std::this_thread::sleep_for(2s);
    const uint64_t now = cpm::get_time_ns();
    double fastest = 0;
    for (uint64_t t = flood_end; t + kSecond / 4 <= now; t += kSecond / 4) {
        auto window = watch.observations_between(t, t + kSecond / 4);
        if (window.size() > 5) fastest = std::max(fastest, mean_speed(window));
    }
    auto recent = watch.observations_between(now - kSecond, now);
    ASSERT_GT(recent.size(), 20u);
    EXPECT_NEAR(mean_speed(recent), 0.5, 0.1);
    EXPECT_LT(fastest, 0.75);
    car.bridge->kill(SIGTERM);
    ASSERT_EQ(car.bridge->wait(5s), 0);
    const auto bridge_stats = last_json_line(car.bridge->output());
    EXPECT_GT(bridge_stats.at("output_discards").get<int>(), 0) << bridge_stats;
    std::printf("flooded %zu bytes in 2 s; %zu states published meanwhile; driving again %.1f s after; fastest "
                "afterwards %.2f m/s; %d cycles dropped the line's backlog\n",
                flooded, during, back_after, fastest, bridge_stats.at("output_discards").get<int>());
}

TEST_F(FirmwareHilEndToEnd, CommandsOutOfRangeStaleForAnotherCarOrWithABadCrcAreNotActedOn)
{
    Car car = avr_car({"--trace-pwm"}, /*start_bridge=*/false);
    Line line(car.device);
    cpm::vehicle::CommandPacket c;
    c.vehicle_id = kId;
    c.motor_mode = cpm::vehicle::MotorMode::forward;
    c.motor_pwm = 300;
    c.servo_us = 1500;
    auto good = line.command_for(c, 300);
    ASSERT_FALSE(good.empty());
    EXPECT_EQ(with_status(good, cpm::vehicle::kStatusBadCommand | cpm::vehicle::kStatusStaleCommand), 0u);
    EXPECT_EQ(good.back().command_tick, line.last_sent_tick()) << "the firmware echoes the tick the last command it applied answered";
    const uint64_t t_bad = cpm::get_time_ns();

    // Stale: answering a state packet sent 300 ms ago (as a command that waited in a backed-up
    // line does), and one from the chip's future (sent before it restarted).
    auto stale = c;
    stale.tick = line.newest_tick() - 300;
    auto states = line.command_for(stale, 200, /*answer_newest=*/false);
    EXPECT_GT(with_status(states, cpm::vehicle::kStatusStaleCommand), 3u);
    auto future = c;
    future.tick = line.newest_tick() + 60'000;
    states = line.command_for(future, 200, /*answer_newest=*/false);
    EXPECT_GT(with_status(states, cpm::vehicle::kStatusStaleCommand), 3u);

    // Out of range: PWM over 1000, a servo pulse outside 1000..2000 us.
    auto pwm_over = c;
    pwm_over.motor_pwm = 1500;
    states = line.command_for(pwm_over, 200);
    EXPECT_GT(with_status(states, cpm::vehicle::kStatusBadCommand), 3u);
    auto servo_over = c;
    servo_over.servo_us = 2600;
    states = line.command_for(servo_over, 200);
    EXPECT_GT(with_status(states, cpm::vehicle::kStatusBadCommand), 3u);
    // None of them was applied: the motor never showed another PWM, and with no valid command
    // for 250 ms the watchdog braked.
    for (const auto& [t, mode] : car.pwm_trace_after(t_bad)) EXPECT_EQ(mode, 0) << "only the watchdog's brake";
    EXPECT_GT(with_status(states, cpm::vehicle::kStatusWatchdogStop), 0u);
    EXPECT_EQ(states.back().command_tick, good.back().command_tick);

    // Another car's command, and a frame whose CRC does not match.
    auto other = c;
    other.vehicle_id = kId + 1;
    states = line.command_for(other, 200);
    EXPECT_GT(with_status(states, cpm::vehicle::kStatusWrongVehicle), 3u);
    auto frame = cpm::vehicle::encode_frame(c);
    frame[4] ^= 0x20;
    for (int i = 0; i < 5; ++i) line.send_raw(frame);
    states = line.states_for(100);
    EXPECT_GT(with_status(states, cpm::vehicle::kStatusBadCrc), 0u);
    for (const auto& [t, mode] : car.pwm_trace_after(t_bad)) EXPECT_EQ(mode, 0);
    EXPECT_EQ(states.back().command_tick, good.back().command_tick);

    // A valid command again is applied at once.
    const uint64_t t_good = cpm::get_time_ns();
    (void)line.command_for(c, 200);
    EXPECT_FALSE(car.pwm_trace_after(t_good, 1).empty()) << car.sim->output();
}

TEST_F(FirmwareHilEndToEnd, ACarDrivenIntoAWallStopsAgainstIt)
{
    Watcher watch(participant);
    const std::string map = "/tmp/cpm_hil_wall_" + std::to_string(::getpid()) + ".json";
    {
        std::ofstream out(map);
        out << R"({"walls": [[1.0, -2.0, 1.0, 2.0]]})";
    }
    Car car = avr_car({"--map", map});
    ASSERT_TRUE(watch.wait_for_states(5)) << car.bridge->errors();
    std::vector<double> front_ranges;
    auto ranges = std::make_unique<cpm::AsyncReader<RangeSensors>>(
        [&](std::vector<RangeSensors>& samples) {
            for (const auto& r : samples) front_ranges.push_back(r.front());
        },
        participant, "rangeSensors");
    {
        Repeater<VehicleCommandSpeedCurvature> command(participant, "vehicleCommandSpeedCurvature", speed_curvature(1.0, 0));
        ASSERT_TRUE(cpm_test::wait_until([&] { return car.sim->errors().find("hit the wall") != std::string::npos; }, 10s))
            << car.sim->errors();
        std::this_thread::sleep_for(1s);
    }
    car.bridge->kill(SIGTERM);
    car.sim->kill(SIGTERM);
    ASSERT_EQ(car.sim->wait(5s), 0);
    ::unlink(map.c_str());
    const double front = 0.40 - 0.07;
    double furthest = -1;
    for (const auto& o : watch.observations()) furthest = std::max(furthest, o.pose().x());
    EXPECT_LE(furthest + front, 1.0 + 1e-6);
    EXPECT_GT(furthest + front, 0.95);
    EXPECT_EQ(last_json_line(car.sim->output()).at("wall_collisions"), 1) << car.sim->output();
    // The front ranger saw the wall: the firmware timed the echo pulse firmware_hil gave it for
    // the distance from the ranger to the wall, and the bridge published it.
    ranges.reset();
    ASSERT_FALSE(front_ranges.empty());
    const double ranger_x = cpm::vehicle::VehicleParameters{}.ultrasonic[0].x;
    EXPECT_NEAR(front_ranges.back(), 1.0 - (furthest + ranger_x), 0.02)
        << "firmware_hil:\n" << car.sim->output() << car.sim->errors() << "bridge:\n" << car.bridge->errors();
    EXPECT_GT(*std::max_element(front_ranges.begin(), front_ranges.end()), 0.7) << "it came closer";
}

TEST_F(FirmwareHilEndToEnd, AWrongFirmwareFileIsNamedAndExitsTwo)
{
    auto fails = [](const std::string& elf, const std::string& says) {
        cpm_test::Process p({cpm_test::built_program("firmware_hil"), elf, "--vehicle_id", "1"});
        EXPECT_EQ(p.wait(10s), 2) << elf;
        EXPECT_NE(p.errors().find(says), std::string::npos) << p.errors();
    };
    fails("/nonexistent/car.elf", "/nonexistent/car.elf: No such file or directory");
    fails("/bin/true", "/bin/true is not a program for an AVR microcontroller");
    fails(CPM_FIRMWARE_HEX, "is not an ELF file (give the .elf avr-gcc made, not the .hex)");
    fails(CPM_OTHER_CHIP_ELF, "is built for atmega328p; firmware_hil runs an atmega2560");
    // A model car other than the one the firmware is built for: its odometer would lie.
    const std::string params = "/tmp/cpm_hil_params_" + std::to_string(::getpid()) + ".json";
    {
        std::ofstream out(params);
        out << R"({"ticks_per_metre": 500})";
    }
    cpm_test::Process other_car({cpm_test::built_program("firmware_hil"), "--vehicle_id", "1", "--params", params});
    EXPECT_EQ(other_car.wait(10s), 2);
    EXPECT_NE(other_car.errors().find("--params " + params + ": vehicle parameter ticks_per_metre is 500, but the firmware is built for 600"),
              std::string::npos)
        << other_car.errors();
    ::unlink(params.c_str());
    cpm_test::Process sim({cpm_test::built_program("cpm"), "vehicle", "sim", "--id", "1", "--firmware", "arm"});
    EXPECT_EQ(sim.wait(10s), 2);
    EXPECT_NE(sim.errors().find("cpm vehicle sim: --firmware is sim (firmware_sim) or avr (the AVR firmware in firmware_hil), not 'arm'"),
              std::string::npos)
        << sim.errors();
}
