// firmware_sim and vehicle_bridge as real processes joined by a real pseudo-terminal; the test
// commands the car over DDS and checks where it really went (VehicleObservation).
#include <cpm/Participant.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/stamp_message.hpp>

#include <cpm_test/Dds.hpp>
#include <cpm_test/Isolation.hpp>
#include <cpm_test/Process.hpp>
#include <cpm_test/RawWriter.hpp>
#include <cpm/vehicle/Protocol.hpp>
#include <cpm/vehicle/SerialPort.hpp>

#include <nlohmann/json.hpp>

#include <RangeSensors.h>
#include <VehicleCommandDirect.h>
#include <VehicleCommandSpeedCurvature.h>
#include <VehicleCommandTrajectory.h>
#include <VehicleObservation.h>
#include <VehicleState.h>

#include <ReadyStatus.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <csignal>
#include <cstring>
#include <fcntl.h>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <random>
#include <set>
#include <sstream>
#include <thread>
#include <unistd.h>

#include "CarHarness.hpp"

namespace {

using namespace car_harness;
using namespace std::chrono_literals;
using cpm_test::built_program;
using cpm_test::Process;

class VehicleEndToEnd : public ::testing::Test
{
protected:
    cpm::Participant participant{cpm_test::isolated_options()};
};

}  // namespace

TEST_F(VehicleEndToEnd, SpeedCurvatureCommandDrivesACircleOfTheCommandedRadius)
{
    Watcher watch(participant);
    Car car;
    ASSERT_TRUE(watch.wait_for_states(5)) << car.bridge->errors();
    Repeater<VehicleCommandSpeedCurvature> command(participant, "vehicleCommandSpeedCurvature", speed_curvature(1.0, 1 / 0.8));
    std::this_thread::sleep_for(1500ms);  // let speed and steering settle
    uint64_t t0 = cpm::get_time_ns();
    std::this_thread::sleep_for(3s);
    auto points = watch.observations_between(t0, cpm::get_time_ns());
    ASSERT_GT(points.size(), 100u);
    // The bridge's calibration describes the simulated car (BridgeCore.CalibrationDescribesTheSimulatedCar):
    // steady on the circle, only the servo's 1 µs steps and the speed loop's ripple are left.
    EXPECT_NEAR(fitted_radius(points), 0.8, 0.02);
    EXPECT_NEAR(mean_speed(points), 1.0, 0.03);
    std::printf("commanded circle: radius %.4f m (0.8), speed %.4f m/s (1.0)\n", fitted_radius(points), mean_speed(points));
}

TEST_F(VehicleEndToEnd, DirectCommandOverridesATrajectoryUntilItIsStale)
{
    Watcher watch(participant);
    Car car;
    ASSERT_TRUE(watch.wait_for_states(5)) << car.bridge->errors();
    // A direct command that holds the car with its wheels hard right, in force first (its
    // writer may take a while to be discovered on a loaded machine) ...
    VehicleCommandDirect direct;
    direct.motor_throttle(0.0);
    direct.steering_servo(-1.0);
    auto override_ = std::make_unique<Repeater<VehicleCommandDirect>>(participant, "vehicleCommandDirect", direct);
    ASSERT_TRUE(cpm_test::wait_until([&] {
        auto s = watch.states();
        return !s.empty() && s.back().steering_servo() == -1.0;
    }, 5s));
    // ... then a trajectory that turns left on a circle of radius 1 m at 0.4 m/s for 10 s; the
    // direct command still wins.
    uint64_t now = cpm::get_time_ns();
    VehicleCommandTrajectory trajectory;
    std::vector<TrajectoryPoint> points;
    for (int i = 0; i <= 100; ++i) {
        const double t = 0.1 * i, v = 0.4, phi = v * t;
        TrajectoryPoint p;
        p.t().nanoseconds(now + uint64_t(i) * kSecond / 10);
        p.px(std::sin(phi));
        p.py(1 - std::cos(phi));
        p.vx(v * std::cos(phi));
        p.vy(v * std::sin(phi));
        points.push_back(p);
    }
    trajectory.trajectory_points(points);
    auto follow = std::make_unique<Repeater<VehicleCommandTrajectory>>(participant, "vehicleCommandTrajectory", trajectory);
    std::this_thread::sleep_for(2s);
    auto states = watch.states();
    ASSERT_FALSE(states.empty());
    EXPECT_DOUBLE_EQ(states.back().motor_throttle(), 0.0);
    EXPECT_DOUBLE_EQ(states.back().steering_servo(), -1.0);
    auto observed = watch.observations();
    ASSERT_FALSE(observed.empty());
    EXPECT_LT(std::hypot(observed.back().pose().x(), observed.back().pose().y()), 0.05);  // held where it stood

    override_.reset();
    // The direct command is stale after 1 s; then the trajectory's again. The car, 3 s behind
    // its reference, catches up on the left-turning circle: steering left on the whole (no
    // command at all would be steering 0 and throttle 0; the direct one, -1 and 0) and on the
    // circle x^2 + (y - 1)^2 = 1 two seconds later.
    const uint64_t released = cpm::get_time_ns();
    uint64_t t_free = 0;
    ASSERT_TRUE(cpm_test::wait_until(
        [&] {
            for (auto& s : watch.states()) {
                if (s.header().create_stamp().nanoseconds() > released && s.steering_servo() != -1.0) {
                    t_free = s.header().create_stamp().nanoseconds();
                    return true;
                }
            }
            return false;
        },
        3s));
    ASSERT_TRUE(cpm_test::wait_until([&] { return !watch.observations_between(t_free + 2 * kSecond, UINT64_MAX).empty(); }, 5s));
    double steering_sum = 0, throttle_sum = 0;
    size_t n = 0;
    for (auto& s : watch.states()) {
        const uint64_t t = s.header().create_stamp().nanoseconds();
        if (t < t_free || t >= t_free + 2 * kSecond) continue;
        steering_sum += s.steering_servo(), throttle_sum += s.motor_throttle(), ++n;
    }
    ASSERT_GT(n, 50u);
    EXPECT_GT(steering_sum / double(n), 0.05);
    EXPECT_GT(throttle_sum / double(n), 0.0);
    const auto on = watch.observations_between(t_free + 2 * kSecond, UINT64_MAX).front().pose();
    EXPECT_NEAR(std::hypot(on.x(), on.y() - 1.0), 1.0, 0.1) << on.x() << ", " << on.y();
    EXPECT_GT(std::hypot(on.x(), on.y()), 0.5);  // and it left the place it was held at
}

TEST_F(VehicleEndToEnd, TrajectoryLineThenArcIsFollowedWithinFiveCentimetres)
{
    Watcher watch(participant);
    Car car;
    ASSERT_TRUE(watch.wait_for_states(5)) << car.bridge->errors();
    uint64_t t0 = cpm::get_time_ns() + kSecond;
    // Accelerate at 1 m/s^2 for 1 s, straight on to x = 2 m, then a left arc of radius 1 m.
    double end = 1.0 + 1.5 + M_PI / 2;
    std::vector<TrajectoryPoint> points;
    for (double t = 0; t <= end + 1e-9; t += 0.1) {
        double s = t < 1 ? 0.5 * t * t : 0.5 + (t - 1), v = std::min(t, 1.0);
        TrajectoryPoint p;
        p.t().nanoseconds(t0 + uint64_t(t * 1e9));
        double phi = std::max(0.0, s - 2.0);
        p.px(s <= 2.0 ? s : 2 + std::sin(phi));
        p.py(s <= 2.0 ? 0.0 : 1 - std::cos(phi));
        p.vx(v * std::cos(phi));
        p.vy(v * std::sin(phi));
        points.push_back(p);
    }
    VehicleCommandTrajectory trajectory;
    trajectory.trajectory_points(points);
    Repeater<VehicleCommandTrajectory> command(participant, "vehicleCommandTrajectory", trajectory);
    std::this_thread::sleep_for(std::chrono::milliseconds(int((end + 1.5) * 1000)));

    auto driven = watch.observations_between(t0, t0 + uint64_t(end * 1e9));
    ASSERT_GT(driven.size(), 150u);
    double worst = 0;
    for (auto& o : driven) {
        double x = o.pose().x(), y = o.pose().y();
        worst = std::max(worst, x <= 2.0 ? std::abs(y) : std::abs(std::hypot(x - 2, y - 1) - 1.0));
    }
    EXPECT_LT(worst, 0.05);
    EXPECT_NEAR(driven.back().pose().x(), 3.0, 0.15);
    EXPECT_NEAR(driven.back().pose().y(), 1.0, 0.15);
    std::printf("worst cross-track error %.1f mm over %zu observations\n", worst * 1000, driven.size());
}

TEST_F(VehicleEndToEnd, KillingTheCommandWriterBrakesTheCarWithinOneSecond)
{
    Watcher watch(participant);
    Car car({"--trace-pwm"});
    cpm::ReaderAbstract<VehicleCommandSpeedCurvature> sent(participant, "vehicleCommandSpeedCurvature", {.keep_all = true});
    Process writer({built_program("vehicle_command_writer"), std::to_string(kId), "0.5", "0"});
    // The newest command the writer sent (a writer starved by a busy machine may have sent it
    // well before the kill).
    uint64_t last_command = 0;
    auto newest_sent = [&] {
        for (const auto& c : sent.take()) last_command = std::max(last_command, c.header().create_stamp().nanoseconds());
        return last_command;
    };
    // The car drives and the test sees the commands too (the test's reader may match the writer
    // later than the bridge does, on a slow machine).
    ASSERT_TRUE(cpm_test::wait_until([&] {
        return !car.pwm_trace_after(0).empty() && car.pwm_trace_after(0).back().second == 1 && newest_sent() > 0;
    }, 10s)) << car.sim->output() << car.bridge->errors() << "\ncommands seen by the test: " << last_command;
    std::this_thread::sleep_for(500ms);
    uint64_t killed = cpm::get_time_ns();
    writer.kill(SIGKILL);
    ASSERT_TRUE(cpm_test::wait_until([&] { return !car.pwm_trace_after(killed, 0).empty(); }, 3s)) << car.sim->output();
    uint64_t braked = car.pwm_trace_after(killed, 0).front().first;
    (void)newest_sent();
    const double after_kill = double(braked - killed) * 1e-9, after_last = double(braked - last_command) * 1e-9;
    // Commands go stale 1 s after their creation; the next bridge cycle (within 20 ms) sends the
    // brake: never before the newest command went stale, and within about a second of the kill.
    EXPECT_GT(after_last, 0.98) << "braked while the newest command was still fresh";
    EXPECT_LT(after_last, 1.1);
    EXPECT_LT(after_kill, 1.1);
    std::printf("braked %.0f ms after the command writer was killed, %.0f ms after its newest command\n", after_kill * 1000,
                after_last * 1000);
}

TEST_F(VehicleEndToEnd, KillingTheBridgeLetsTheWatchdogBrakeWithin250ms)
{
    Watcher watch(participant);
    Car car({"--trace-pwm"});
    Repeater<VehicleCommandSpeedCurvature> command(participant, "vehicleCommandSpeedCurvature", speed_curvature(0.5, 0));
    ASSERT_TRUE(cpm_test::wait_until([&] { return !car.pwm_trace_after(0).empty() && car.pwm_trace_after(0).back().second == 1; }, 10s))
        << car.sim->output() << car.bridge->errors();
    std::this_thread::sleep_for(500ms);
    uint64_t killed = cpm::get_time_ns();
    car.bridge->kill(SIGKILL);
    ASSERT_TRUE(cpm_test::wait_until([&] { return !car.pwm_trace_after(killed, 0).empty(); }, 3s)) << car.sim->output();
    uint64_t braked = car.pwm_trace_after(killed, 0).front().first;
    double after = double(braked - killed) * 1e-9;
    // The watchdog fires 250 ms after the last command, which came up to one cycle (20 ms)
    // before the kill; the simulator's 4 ms ticks and a busy machine may add a few ms.
    EXPECT_GT(after, 0.2);
    EXPECT_LT(after, 0.3);
    car.sim->kill(SIGTERM);
    ASSERT_EQ(car.sim->wait(5s), 0);
    // The brake is the watchdog's (the bridge is dead), and the car was stopped once while it
    // drove: at the kill. The watchdog also counts a stop before the first command when the
    // bridge takes over 250 ms to start (seen with a busy loop beside), the car standing then.
    EXPECT_GE(last_json_line(car.sim->output()).at("watchdog_stops").get<int>(), 1) << car.sim->output();
#ifdef CPM_TEST_SANITIZED
    // A bridge starved by the sanitizer may let the watchdog stop the car once more while driving.
    EXPECT_GE(car.stops_while_driving(), 1) << car.sim->output();
#else
    EXPECT_EQ(car.stops_while_driving(), 1) << car.sim->output();
#endif
    std::printf("watchdog braked %.0f ms after the bridge was killed\n", after * 1000);
}

TEST_F(VehicleEndToEnd, CorruptBytesOnTheLineAreSurvivedBothWays)
{
    Watcher watch(participant);
    Car car({"--corrupt-rate", "0.2"});  // one state frame in five corrupted on its way to the bridge
    ASSERT_TRUE(watch.wait_for_states(5)) << car.bridge->errors();
    Repeater<VehicleCommandSpeedCurvature> command(participant, "vehicleCommandSpeedCurvature", speed_curvature(0.5, 0));
    write_garbage_bursts(car.device);  // towards the microcontroller, between the bridge's commands
    expect_driving_through_corruption(watch);

    car.bridge->kill(SIGTERM);
    car.sim->kill(SIGTERM);
    ASSERT_EQ(car.bridge->wait(5s), 0);
    ASSERT_EQ(car.sim->wait(5s), 0);
    // Both ends counted what they threw away (their statistics are one JSON line each).
    auto bridge_stats = last_json_line(car.bridge->output());
    auto sim_stats = last_json_line(car.sim->output());
    EXPECT_GT(bridge_stats.at("decoder_errors").get<int>(), 0) << bridge_stats;
    EXPECT_GT(bridge_stats.at("cycles").get<int>(), 50) << bridge_stats;
    const auto& sim_errors = sim_stats.at("decoder_errors");
    EXPECT_GT(sim_errors.at("bad_cobs").get<int>() + sim_errors.at("too_short").get<int>() +
                  sim_errors.at("bad_crc").get<int>() + sim_errors.at("oversize").get<int>(),
              0)
        << sim_stats;
}

TEST_F(VehicleEndToEnd, MalformedCommandSamplesFromAnyParticipantAreDroppedAndTheBridgeKeepsDriving)
{
    // Anyone on the domain may send bytes that are not a command (found by fuzzing: a wrong
    // encapsulation made the generated type support throw through Fast DDS into the reader).
    Car car({"--trace-pwm"});
    cpm::Participant stranger{cpm_test::isolated_options()};
    cpm_test::RawWriter raw(stranger, "vehicleCommandSpeedCurvature", "VehicleCommandSpeedCurvature", true);
    ASSERT_TRUE(cpm_test::wait_until([&] { return raw.matched() > 0; }, 10s)) << car.bridge->errors();
    // Encapsulation, Header (create, valid_after), vehicle_id at offset 20, speed, curvature.
    std::vector<uint8_t> command(4 + 16 + 8 + 16, 0);
    command[1] = 0x01;  // CDR little endian
    command[20] = kId;
    const double speed = 0.5;
    std::memcpy(&command[28], &speed, sizeof speed);
    std::vector<std::vector<uint8_t>> malformed;
    for (uint8_t first : {0x01, 0x7f, 0xff}) {
        auto m = command;
        m[0] = first;  // not an encapsulation Fast CDR knows
        malformed.push_back(m);
    }
    malformed.push_back({command.begin(), command.begin() + 22});  // cut off
    malformed.push_back({});                                        // empty
    for (int round = 0; round < 20; ++round)
        for (const auto& m : malformed) ASSERT_TRUE(raw.write(m));
    std::this_thread::sleep_for(500ms);
    const uint64_t after_malformed = cpm::get_time_ns();
    Repeater<VehicleCommandSpeedCurvature> good(participant, "vehicleCommandSpeedCurvature", speed_curvature(0.5, 0));
    EXPECT_TRUE(cpm_test::wait_until([&] { return !car.pwm_trace_after(after_malformed, 1).empty(); }, 10s))
        << "the car did not drive on the good command after the malformed ones\nbridge: " << car.bridge->errors();
    EXPECT_EQ(car.bridge->errors().find("terminate called"), std::string::npos) << car.bridge->errors();
}

TEST_F(VehicleEndToEnd, BridgeStopsPublishingWhenTheLinkIsLostAndReconnects)
{
    Watcher watch(participant);
    std::string link = "/tmp/cpm_vehicle_test_" + std::to_string(::getpid()) + ".tty";
    Car car({"--link", link}, false, 21);
    car.start_bridge(link);
    ASSERT_TRUE(watch.wait_for_states(5)) << car.bridge->errors();
    const uint64_t killed = cpm::get_time_ns();
    car.sim->kill(SIGKILL);
    car.sim->wait(5s);
    std::this_thread::sleep_for(1s);
    // Nothing measured after the car was gone is published (what was still in the line is
    // published with its real, older time).
    EXPECT_EQ(watch.states_created_after(killed + 25'000'000), 0u);
    EXPECT_NE(car.bridge->errors().find("serial link to " + link + " lost"), std::string::npos) << car.bridge->errors();

    const uint64_t restarted = cpm::get_time_ns();
    car.start_sim({"--link", link});
    EXPECT_TRUE(cpm_test::wait_until([&] { return watch.states_created_after(restarted) >= 20; }, 10s))
        << car.bridge->errors();
    EXPECT_EQ(car.bridge->wait(0ms), -1);  // the same bridge process, still running
    ::unlink(link.c_str());
}

TEST_F(VehicleEndToEnd, ABridgeLeavesALineWhoseControllerBelongsToAnotherVehicle)
{
    Watcher watch(participant);
    Car car({}, false);  // vehicle 7's controller
    car.start_bridge({}, 9);
    EXPECT_TRUE(cpm_test::wait_until([&] { return car.bridge->errors().find("belongs to vehicle 7") != std::string::npos; }))
        << car.bridge->errors();
    // And it stays off the line: no state for a whole second after it said so (one look at once
    // would pass a bridge that published a moment later).
    EXPECT_TRUE(cpm_test::holds_for([&] { return watch.states().empty(); }, 1000ms)) << watch.states().size() << " states published";
}

TEST_F(VehicleEndToEnd, ASecondBridgeOnTheSameLineIsRefusedAndTheFirstKeepsDriving)
{
    Watcher watch(participant);
    Car car;
    ASSERT_TRUE(watch.wait_for_states(5)) << car.bridge->errors();
    Process second({built_program("vehicle_bridge"), "--vehicle_id", std::to_string(kId), "--device", car.device});
    EXPECT_TRUE(cpm_test::wait_until([&] { return second.errors().find("in use by another program") != std::string::npos; }))
        << second.errors();
    // Counted by the states' own stamps over one second of the car's time, not by how long
    // this test happened to sleep on a busy machine.
    const uint64_t t = cpm::get_time_ns();
    ASSERT_TRUE(cpm_test::wait_until([&] { return watch.states_created_after(t + kSecond) > 0; }, 10s));
    const size_t in_one_second = watch.states_created_after(t) - watch.states_created_after(t + kSecond);
    EXPECT_GE(in_one_second, 45u) << "gaps: " << watch.state_gaps_between(t, t + kSecond) << "\nfirst bridge:\n"
                                  << car.bridge->errors() << "simulator:\n" << car.sim->errors();  // still 50 Hz
    EXPECT_LE(in_one_second, 51u);  // from the first bridge only
}

TEST_F(VehicleEndToEnd, OneSimulatorAndOneBridgeProcessCarryTwentyCarsEachOnItsOwnCommand)
{
    // 20 cars in a row 1 m apart, all in one firmware_sim and one vehicle_bridge process; only
    // car 25 is commanded. Every car must report at 50 Hz, car 25 drive, the others stay put.
    cpm::ReaderAbstract<VehicleState> states(participant, "vehicleState", {.keep_all = true});
    cpm::ReaderAbstract<VehicleObservation> observations(participant, "vehicleObservation", {.keep_all = true});
    Process sut({built_program("cpm"), "vehicle", "sim", "--id", "11", "--count", "20", "--spacing", "1.0", "--realtime"});
    std::set<std::string> sim_pids, bridge_pids;
    ASSERT_TRUE(cpm_test::wait_until([&] { return count_of(sut.output(), "vehicle_bridge pid ") == 20; }, 20s))
        << sut.output() << sut.errors();
    std::istringstream lines(sut.output());
    for (std::string line; std::getline(lines, line);) {
        const auto sim = line.find("firmware_sim pid "), bridge = line.find("vehicle_bridge pid ");
        if (sim == std::string::npos || bridge == std::string::npos) continue;
        sim_pids.insert(line.substr(sim + 17, line.find(' ', sim + 17) - sim - 17));
        bridge_pids.insert(line.substr(bridge + 19, line.find(',', bridge + 19) - bridge - 19));
    }
    EXPECT_EQ(sim_pids.size(), 1u) << sut.output();
    EXPECT_EQ(bridge_pids.size(), 1u) << sut.output();

    Repeater<VehicleCommandSpeedCurvature> command(participant, "vehicleCommandSpeedCurvature", speed_curvature(0.5, 0), 25);
    std::map<int, std::vector<uint64_t>> stamps;
    std::map<int, std::pair<VehicleObservation, VehicleObservation>> first_last;
    ASSERT_TRUE(cpm_test::wait_until([&] {
        for (auto& s : states.take()) stamps[s.vehicle_id()].push_back(s.header().create_stamp().nanoseconds());
        return stamps.size() == 20;
    }, 20s)) << sut.errors();
    states.take();
    observations.take();
    const uint64_t t0 = cpm::get_time_ns() + 500'000'000ull, t1 = t0 + 3 * kSecond;  // a 3 s window after a settling 0.5 s
    stamps.clear();
    while (cpm::get_time_ns() < t1 + 300'000'000ull) {
        for (auto& s : states.take()) stamps[s.vehicle_id()].push_back(s.header().create_stamp().nanoseconds());
        for (auto& o : observations.take()) {
            const uint64_t t = o.header().create_stamp().nanoseconds();
            if (t < t0 || t >= t1) continue;
            auto [it, fresh] = first_last.try_emplace(o.vehicle_id(), o, o);
            if (!fresh) it->second.second = o;
        }
        std::this_thread::sleep_for(20ms);
    }
    for (int id = 11; id <= 30; ++id) {
        const auto n = std::count_if(stamps[id].begin(), stamps[id].end(), [&](uint64_t t) { return t >= t0 && t < t1; });
        // Each car runs its own loop thread: on a busy 2-core machine one of twenty may lose a
        // tick or five in a 3 s window (1 run in 5 beside a busy loop lost 5 for one car). A car
        // that stalls or runs at another rate still fails; the fleet's capacity is bench_vehicle's.
        EXPECT_GE(n, 142) << "vehicle " << id << ": 50 Hz for 3 s, under 5 % missed";
        EXPECT_LE(n, 151) << "vehicle " << id << ": 50 Hz for 3 s";
        ASSERT_TRUE(first_last.count(id)) << "vehicle " << id;
        const auto& [a, b] = first_last[id];
        const double moved = std::hypot(b.pose().x() - a.pose().x(), b.pose().y() - a.pose().y());
        if (id == 25) {
            EXPECT_GT(moved, 1.2) << "the commanded car drives (0.5 m/s for 3 s)";
        } else {
            EXPECT_LT(moved, 0.05) << "vehicle " << id << " was not commanded";
        }
    }
    sut.kill(SIGINT);
    EXPECT_EQ(sut.wait(15s), 0) << sut.errors();
    EXPECT_EQ(count_of(sut.output(), "\"cycles\""), 20u) << "one statistics line per car from the bridge";
    EXPECT_EQ(count_of(sut.output(), "\"state_packets\""), 20u) << "one statistics line per car from the simulator";
}

TEST_F(VehicleEndToEnd, InSimulatedTimeTheCarsWaitForTheLabClockAndStillStopOnCtrlC)
{
    cpm::ReaderAbstract<VehicleState> states(participant, "vehicleState", {.keep_all = true});
    cpm::ReaderAbstract<ReadyStatus> ready(participant, "readyStatus", {.reliable = true, .history_depth = 10, .transient_local = true});
    Process sut({built_program("cpm"), "vehicle", "sim", "--id", "4", "--count", "2", "--simulated_time"});
    ASSERT_TRUE(cpm_test::wait_until([&] {
        return sut.output().find("cpm lab clock --simulated --nodes firmware_sim_4,vehicle_bridge_4") != std::string::npos;
    }, 10s)) << sut.output() << sut.errors();
    // Both processes wait on the lab's clock: each announced its first tick (a busy machine starts
    // them later than the message above).
    std::set<std::string> waiting;
    ASSERT_TRUE(cpm_test::wait_until([&] {
        for (auto& r : ready.take()) waiting.insert(r.source_id());
        return waiting.count("firmware_sim_4") && waiting.count("vehicle_bridge_4");
    }, 20s)) << sut.errors() << "announced: " << ::testing::PrintToString(waiting);
    EXPECT_TRUE(cpm_test::holds_for([&] { return states.take().empty(); }, 1000ms)) << "no lab clock runs: no car may tick";
    // Ctrl-C while the clock stands still: every process ends at once and reports.
    const auto t0 = std::chrono::steady_clock::now();
    sut.kill(SIGINT);
    EXPECT_EQ(sut.wait(10s), 0) << sut.errors();
    EXPECT_LT(std::chrono::steady_clock::now() - t0, 4s) << "a child had to be killed after its 5 s grace";
    EXPECT_EQ(count_of(sut.output(), "\"cycles\":0"), 2u) << sut.output();
    EXPECT_EQ(count_of(sut.output(), "\"state_packets\":0"), 2u) << sut.output();
}

TEST_F(VehicleEndToEnd, ManyCarFlagsThatDoNotAddUpAreNamed)
{
    const auto fails = [](std::vector<std::string> argv, int code, const std::string& message) {
        argv[0] = built_program(argv[0]);
        Process p(argv);
        EXPECT_EQ(p.wait(10s), code) << p.errors();
        EXPECT_NE(p.errors().find(message), std::string::npos) << p.errors();
    };
    fails({"firmware_sim", "--vehicle_id", "3,4,3"}, 2, "--vehicle_id: vehicle 3 is listed twice");
    fails({"firmware_sim", "--vehicle_id", "3,4", "--start", "0,0,0"}, 2, "--start: 1 pose(s) for 2 car(s)");
    fails({"firmware_sim", "--vehicle_id", "3,4", "--start", "0,0,0;1,x,0"}, 2, "--start (pose 2)");
    fails({"firmware_sim", "--vehicle_id", "3,4", "--trace-pwm"}, 2, "--trace-pwm is for one car; --vehicle_id lists 2");
    fails({"vehicle_bridge", "--vehicle_id", "3,4", "--device", "/dev/null"}, 2, "--device names 1 device(s) for 2 car(s)");
    fails({"vehicle_bridge", "--vehicle_id", "3,0", "--device", "/dev/null,/dev/null"}, 2, "--vehicle_id");
    // A device that is no terminal ends a many-car bridge as it ends a one-car bridge.
    fails({"vehicle_bridge", "--vehicle_id", "3,4", "--device", "/dev/null,/dev/null"}, 1, "/dev/null: not a terminal device");
}

TEST_F(VehicleEndToEnd, WrongFilesAndFlagsAreNamedAndExitNonZero)
{
    Process no_map({built_program("firmware_sim"), "--vehicle_id", "1", "--map", "/nonexistent/map.json"});
    EXPECT_EQ(no_map.wait(10s), 1);
    EXPECT_NE(no_map.errors().find("/nonexistent/map.json: cannot open the map file: no such file"), std::string::npos) << no_map.errors();
    Process bad_start({built_program("firmware_sim"), "--vehicle_id", "1", "--start", "1,2"});
    EXPECT_EQ(bad_start.wait(10s), 2);
    EXPECT_NE(bad_start.errors().find("--start: expected X,Y,YAW"), std::string::npos) << bad_start.errors();
    Process no_device({built_program("vehicle_bridge"), "--vehicle_id", "1"});
    EXPECT_EQ(no_device.wait(10s), 2);
    EXPECT_NE(no_device.errors().find("--device is required"), std::string::npos) << no_device.errors();
    Process bad_baud({built_program("vehicle_bridge"), "--vehicle_id", "1", "--device", "/dev/null", "--baud", "12345"});
    EXPECT_EQ(bad_baud.wait(10s), 2);
    EXPECT_NE(bad_baud.errors().find("unsupported baud rate 12345"), std::string::npos) << bad_baud.errors();
    Process not_a_tty({built_program("vehicle_bridge"), "--vehicle_id", "1", "--device", "/dev/null"});
    EXPECT_EQ(not_a_tty.wait(10s), 1);
    EXPECT_NE(not_a_tty.errors().find("/dev/null: not a terminal device"), std::string::npos) << not_a_tty.errors();
}

TEST_F(VehicleEndToEnd, CpmVehicleSimPassesItsDdsFlagsToTheProgramsItStarts)
{
    // `cpm vehicle sim --dds_domain N` must put its simulator and bridge on domain N too (they
    // once fell back to the environment's domain). Here N is this test's own domain, so a
    // failure cannot leak into another test's; the children's command lines tell.
    const std::string domain = std::to_string(cpm_test::test_domain_id());
    Process sut({built_program("cpm"), "vehicle", "sim", "--id", "9", "--dds_domain", domain});
    std::string sim_pid, bridge_pid;
    ASSERT_TRUE(cpm_test::wait_until([&] {
        std::istringstream out(sut.output());
        for (std::string line; std::getline(out, line);) {
            const auto sim = line.find("firmware_sim pid "), bridge = line.find("vehicle_bridge pid ");
            if (sim == std::string::npos || bridge == std::string::npos) continue;
            sim_pid = line.substr(sim + 17, line.find(' ', sim + 17) - sim - 17);
            bridge_pid = line.substr(bridge + 19, line.find(',', bridge + 19) - bridge - 19);
            return true;
        }
        return false;
    }, 10s)) << sut.output() << sut.errors();
    for (const auto& [pid, program] : {std::pair{sim_pid, "firmware_sim"}, std::pair{bridge_pid, "vehicle_bridge"}}) {
        std::string cmdline;
        EXPECT_TRUE(cpm_test::wait_until([&] {  // once the child has replaced itself with the program
            std::ifstream in("/proc/" + pid + "/cmdline");
            cmdline.assign(std::istreambuf_iterator<char>(in), {});
            std::replace(cmdline.begin(), cmdline.end(), '\0', ' ');
            return cmdline.find(program) != std::string::npos;
        }, 5s)) << cmdline;
        EXPECT_NE(cmdline.find("--dds_domain " + domain), std::string::npos) << program << " " << pid << ": " << cmdline;
    }
    sut.kill(SIGINT);
    EXPECT_EQ(sut.wait(10s), 0) << sut.errors();
}

TEST_F(VehicleEndToEnd, CpmVehicleSimStartsCarsThatSeeEachOther)
{
    cpm::ReaderAbstract<RangeSensors> ranges(participant, "rangeSensors", {.keep_all = true});
    // Car 7 at the origin, car 8 one metre behind it; both face +x in an empty world.
    Process sut({built_program("cpm"), "vehicle", "sim", "--id", "7", "--count", "2", "--spacing", "1.0"});
    std::map<int, double> front;
    ASSERT_TRUE(cpm_test::wait_until([&] {
        for (auto& r : ranges.take()) front[r.vehicle_id()] = r.front();
        return front.size() == 2 && front[8] < 1.0;
    }, 10s)) << sut.output() << sut.errors();
    // Car 8's front ranger (0.30 m ahead of its rear axle, at x = -0.70) sees car 7's rear
    // (0.07 m behind its rear axle, at x = -0.07); nothing is in front of car 7.
    EXPECT_NEAR(front[8], 0.63, 0.02);
    EXPECT_EQ(front[7], 3.0);
    sut.kill(SIGINT);
    EXPECT_EQ(sut.wait(10s), 0) << sut.errors();
    // Each car's bridge and simulator print their statistics as one JSON line when stopped.
    std::map<std::pair<int, std::string>, nlohmann::json> stats;
    std::istringstream out(sut.output());
    for (std::string line; std::getline(out, line);) {
        if (line.empty() || line[0] != '{') continue;
        auto j = nlohmann::json::parse(line);
        stats[{j["vehicle_id"].get<int>(), j.contains("cycles") ? "bridge" : "sim"}] = j;
    }
    for (int id : {7, 8}) {
        const std::pair<int, std::string> bridge{id, "bridge"}, sim{id, "sim"};
        ASSERT_TRUE(stats.count(bridge)) << id << "\n" << sut.output();
        ASSERT_TRUE(stats.count(sim)) << id << "\n" << sut.output();
        EXPECT_GT(stats[bridge]["cycles"].get<int>(), 0);
        EXPECT_GT(stats[sim]["state_packets"].get<int>(), 0);
    }
}

namespace {

/// The test as the car's microcontroller: crafted state frames into a real pseudo-terminal, at
/// 50 Hz of the test's own clock, and the bridge's command packets read back from it.
class CraftedController
{
public:
    const std::string& device() const { return pty_.device_path(); }
    /// Writes one state frame and collects the commands the bridge sent so far.
    void send(const cpm::vehicle::StatePacket& packet)
    {
        auto frame = cpm::vehicle::encode_frame(packet);
        pty_.write_frame(frame.data(), frame.size());
        uint8_t buffer[512];
        for (long n; (n = pty_.read_available(buffer, sizeof buffer)) > 0;) {
            decoder_.feed(buffer, size_t(n), [&](const cpm::vehicle::Packet& p) {
                if (auto* c = std::get_if<cpm::vehicle::CommandPacket>(&p)) commands_.push_back(*c);
            });
        }
    }
    const std::vector<cpm::vehicle::CommandPacket>& commands() const { return commands_; }

private:
    cpm::vehicle::PseudoTerminal pty_;
    cpm::vehicle::FrameDecoder decoder_;
    std::vector<cpm::vehicle::CommandPacket> commands_;
};

}  // namespace

TEST_F(VehicleEndToEnd, CraftedFramesOnAPtyAreCheckedRebasedAndLoggedOnceASecond)
{
    Watcher watch(participant);
    CraftedController controller;
    Process bridge({built_program("vehicle_bridge"), "--vehicle_id", std::to_string(kId), "--device", controller.device(), "--realtime"});
    cpm::vehicle::StatePacket p;
    p.vehicle_id = kId;
    p.tick = 100'000;
    p.battery_mv = 8000;
    p.speed_mm_s = 500;
    cpm::vehicle::StatePacket foreign = p;
    foreign.vehicle_id = 9;
    int sent = 0, foreign_sent = 0;
    auto step = [&](bool with_foreign) {  // one 20 ms period: 1 cm further
        p.tick += 20;
        p.odometer_steps += 6;
        controller.send(p);
        if (with_foreign) {
            foreign.tick = p.tick;
            controller.send(foreign);
            ++foreign_sent;
        }
        ++sent;
        std::this_thread::sleep_for(20ms);
    };
    for (int i = 0; i < 500 && watch.states().empty(); ++i) step(false);
    ASSERT_FALSE(watch.states().empty()) << bridge.errors();

    // Another car's frame every 10th period (5 per second) for 3 s: ignored, the line is kept.
    const size_t states_before = watch.states().size();
    for (int i = 0; i < 150; ++i) step(i % 10 == 0);
    ASSERT_TRUE(cpm_test::wait_until([&] { return watch.states().size() >= states_before + 140; }, 5s))
        << watch.states().size() - states_before << " states in 150 periods\n" << bridge.errors();

    // One NaN speed, then a valid command: the NaN never drives, the valid one does at once.
    // The one NaN sample is sent every period (the same sample: one create_stamp), since the
    // bridge's best-effort reader may match this writer a moment after the writer matched it.
    cpm::Writer<VehicleCommandSpeedCurvature> commands(participant, "vehicleCommandSpeedCurvature");
    ASSERT_TRUE(commands.wait_for_matched(1, 10s));
    auto command = speed_curvature(std::nan(""), 0);
    command.vehicle_id(kId);
    cpm::stamp_message(command, cpm::get_time_ns(), 0);
    for (int i = 0; i < 15; ++i) {
        ASSERT_TRUE(commands.write(command));
        step(false);
    }
    const size_t commands_before_valid = controller.commands().size();
    for (const auto& c : controller.commands()) ASSERT_EQ(c.motor_mode, cpm::vehicle::MotorMode::brake);
    command.speed(0.5);
    auto after_valid = [&] {
        return std::vector<cpm::vehicle::CommandPacket>(controller.commands().begin() + long(commands_before_valid), controller.commands().end());
    };
    auto driving = [&] {
        const auto a = after_valid();
        return !a.empty() && a.back().motor_mode == cpm::vehicle::MotorMode::forward;
    };
    // A period after another while the bridge answers (25 periods on an idle machine; the
    // deadline is for a busy one).
    for (int i = 0; i < 25 || (i < 250 && !driving()); ++i) {
        cpm::stamp_message(command, cpm::get_time_ns(), 0);
        ASSERT_TRUE(commands.write(command));
        step(false);
    }
    ASSERT_FALSE(after_valid().empty()) << bridge.errors();
    EXPECT_EQ(after_valid().back().motor_mode, cpm::vehicle::MotorMode::forward);
    EXPECT_GT(after_valid().back().motor_pwm, 0);

    // The controller restarts (tick and odometer from zero), then an odometer jump of 5 km with
    // a battery reading of 0 V: the pose never moves back, the odometer never leaps, no 0 V.
    p.tick = 0;
    p.odometer_steps = 0;
    for (int i = 0; i < 10; ++i) step(false);
    p.odometer_steps += 600 * 5000;
    p.battery_mv = 0;
    step(false);
    p.battery_mv = 8000;
    for (int i = 0; i < 10; ++i) step(false);

    bridge.kill(SIGTERM);
    ASSERT_EQ(bridge.wait(10s), 0) << bridge.errors();
    const auto states = watch.states();
    double x = -1e9;
    for (const auto& s : states) {
        EXPECT_GE(s.pose().x(), x - 1e-9) << "the pose moved back";
        x = std::max(x, s.pose().x());
        EXPECT_LT(s.odometer_distance(), 10.0);
        EXPECT_DOUBLE_EQ(s.battery_voltage(), 8.0);
        EXPECT_TRUE(std::isfinite(s.motor_throttle()));
    }
    auto stats = last_json_line(bridge.output());
    EXPECT_EQ(stats["refused_commands"], 1) << stats;
    EXPECT_EQ(stats["controller_restarts"], 1) << stats;
    EXPECT_EQ(stats["odometer_jumps"], 1) << stats;
    EXPECT_EQ(stats["battery_out_of_range"], 1) << stats;
    EXPECT_EQ(stats["foreign_packets"], foreign_sent) << stats;
    EXPECT_EQ(stats["foreign_controller"], 0) << stats;
    const auto log = bridge.errors();
    EXPECT_EQ(count_of(log, "leaving the line"), 0u) << log;
    EXPECT_EQ(count_of(log, "serial link open"), 1u) << log;  // never left and rejoined
    // 15 foreign frames over 3 s: reported at most once a second.
    EXPECT_GE(count_of(log, "ignored a state packet from the controller of vehicle 9"), 1u) << log;
    EXPECT_LE(count_of(log, "ignored a state packet from the controller of vehicle 9"), 4u) << log;
    EXPECT_EQ(count_of(log, "refused a speed_curvature command"), 1u) << log;
    EXPECT_NE(log.find("speed = nan is not a finite number"), std::string::npos) << log;
    EXPECT_EQ(count_of(log, "the controller restarted"), 1u) << log;
    EXPECT_EQ(count_of(log, "odometer jumped by 5000.01 m"), 1u) << log;
    EXPECT_EQ(count_of(log, "battery reads 0.000 V"), 1u) << log;
}

TEST_F(VehicleEndToEnd, ACarDrivenIntoAWallStopsAgainstItAndTheSimulatorReportsIt)
{
    Watcher watch(participant);
    const std::string map = "/tmp/cpm_vehicle_wall_" + std::to_string(::getpid()) + ".json";
    {
        std::ofstream out(map);
        out << R"({"walls": [[1.0, -2.0, 1.0, 2.0]]})";  // across the road, 1 m ahead of the rear axle
    }
    Car car({"--map", map});
    ASSERT_TRUE(watch.wait_for_states(5)) << car.bridge->errors();
    {
        Repeater<VehicleCommandSpeedCurvature> command(participant, "vehicleCommandSpeedCurvature", speed_curvature(1.0, 0));
        ASSERT_TRUE(cpm_test::wait_until([&] { return car.sim->errors().find("hit the wall") != std::string::npos; }, 10s))
            << car.sim->errors();
        std::this_thread::sleep_for(1s);  // still commanded forward, against the wall
    }
    car.bridge->kill(SIGTERM);
    car.sim->kill(SIGTERM);
    ASSERT_EQ(car.sim->wait(5s), 0);
    ::unlink(map.c_str());
    const double front = 0.40 - 0.07;  // body length minus rear overhang: the bumper ahead of the axle
    double furthest = -1;
    for (const auto& o : watch.observations()) furthest = std::max(furthest, o.pose().x());
    EXPECT_LE(furthest + front, 1.0 + 1e-6);  // never through it
    EXPECT_GT(furthest + front, 0.95);        // but right up against it
    EXPECT_EQ(last_json_line(car.sim->output()).at("wall_collisions"), 1) << car.sim->output();
    EXPECT_NE(car.sim->errors().find("vehicle 7: hit the wall [1.000, -2.000, 1.000, 2.000]"), std::string::npos)
        << car.sim->errors();
}
