// firmware_sim: plays a car's microcontroller behind a pseudo-terminal (see README.md).
#include <cpm/CommandLine.hpp>
#include <cpm/Participant.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/Timer.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/init.hpp>
#include <cpm/stamp_message.hpp>
#include <cpm/vehicle/FirmwareSim.hpp>
#include <cpm/vehicle/SerialPort.hpp>

#include <VehicleObservation.h>

#include <csignal>
#include <cstdio>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <thread>

namespace {

const char* kHelp =
    "usage: firmware_sim --vehicle_id N [--map FILE] [--params FILE] [--start X,Y,YAW]\n"
    "                    [--link PATH | --device TTY [--baud B]] [--seed N] [--trace-pwm]\n"
    "                    [--corrupt-rate P] [--dds_domain N]\n"
    "\n"
    "Plays vehicle N's microcontroller: opens a pseudo-terminal, prints its device path as\n"
    "`device: /dev/pts/K` and then speaks the serial protocol on it (state packets at\n"
    "state_rate, commands in; vehicle model at physics_rate; watchdog brakes after 250 ms\n"
    "without a valid command). Publishes the true pose as VehicleObservation on\n"
    "'vehicleObservation' and sees other simulated cars' bodies with its rangers.\n"
    "\n"
    "  --map FILE      world of walls (JSON, DESIGN.md §6); default: no walls\n"
    "  --params FILE   vehicle parameters (JSON; see vehicle_firmware_bridge/README.md)\n"
    "  --start X,Y,YAW start pose in metres and radians (default 0,0,0)\n"
    "  --link PATH     also make PATH a symlink to the device (a stable name across restarts)\n"
    "  --device TTY    speak on this existing serial device instead of a new pty (e.g. one end of\n"
    "                  a null-modem cable to a bridge on another computer); --baud B (115200)\n"
    "  --seed N        noise seed (default: the vehicle id)\n"
    "  --trace-pwm     print `pwm T_NS MODE PWM` on stdout whenever the motor command the controller\n"
    "                  holds changes (a new command, or the watchdog's brake; MODE 0 brake, 1 fwd, 2 rev)\n"
    "  --corrupt-rate P  flip one random byte in a state frame with probability P (tests the link)\n"
    "On SIGINT/SIGTERM it prints one JSON line of statistics and exits 0.\n";

int run(int argc, char** argv)
{
    std::vector<std::string> args(argv + 1, argv + argc);
    auto parsed = cpm::cli::parse_args(args,
                                       {{"--vehicle_id", true}, {"--map", true}, {"--params", true}, {"--start", true},
                                        {"--link", true}, {"--seed", true}, {"--trace-pwm", false},
                                        {"--corrupt-rate", true}, {"--device", true}, {"--baud", true}},
                                       "firmware_sim");
    if (!parsed.positional.empty()) throw cpm::cli::UsageError("firmware_sim: unexpected argument '" + parsed.positional[0] + "'");
    if (!parsed.has("--vehicle_id")) throw cpm::cli::UsageError("firmware_sim: --vehicle_id is required");
    auto vehicle_id = static_cast<uint8_t>(cpm::cli::parse_integer("--vehicle_id", parsed.get("--vehicle_id"), 1, 255));
    auto parameters = parsed.has("--params") ? cpm::vehicle::VehicleParameters::load(parsed.get("--params"))
                                             : cpm::vehicle::VehicleParameters{};
    auto world = parsed.has("--map") ? cpm::vehicle::World::load(parsed.get("--map")) : cpm::vehicle::World{};
    auto start = parsed.has("--start") ? cpm::vehicle::parse_pose("--start", parsed.get("--start")) : cpm::vehicle::Pose{};
    auto seed = static_cast<uint32_t>(parsed.has("--seed") ? cpm::cli::parse_integer("--seed", parsed.get("--seed"), 0, UINT32_MAX)
                                                           : vehicle_id);
    bool trace_pwm = parsed.has("--trace-pwm");
    double corrupt_rate = cpm::cli::parse_number("--corrupt-rate", parsed.get("--corrupt-rate", "0"), 0, 1);
    std::mt19937 corruption(seed);
    cpm::init(argc, argv);

    if (parsed.has("--device") && parsed.has("--link")) {
        throw cpm::cli::UsageError("firmware_sim: --link names a new pty; it cannot go with --device");
    }
    int baud = int(cpm::cli::parse_integer("--baud", parsed.get("--baud", "115200"), 1, 4'000'000));

    cpm::vehicle::FirmwareSim sim(parameters, std::move(world), start, vehicle_id, seed);
    // The line to the host: a new pseudo-terminal, or a serial device that already exists.
    std::unique_ptr<cpm::vehicle::PseudoTerminal> pty;
    std::unique_ptr<cpm::vehicle::SerialPort> port;
    if (parsed.has("--device")) {
        port = std::make_unique<cpm::vehicle::SerialPort>(parsed.get("--device"), baud);
    } else {
        pty = std::make_unique<cpm::vehicle::PseudoTerminal>(parsed.get("--link"));
    }
    auto read_line = [&](uint8_t* data, size_t size) {
        return pty ? pty->read_available(data, size) : port->read_some(data, size, 0);
    };
    auto write_line = [&](const std::vector<uint8_t>& frame) {
        return pty ? pty->write_frame(frame.data(), frame.size()) : port->write_all(frame.data(), frame.size());
    };
    std::printf("device: %s\n", pty ? pty->device_path().c_str() : parsed.get("--device").c_str());
    std::fflush(stdout);

    cpm::Participant& participant = cpm::Participant::default_participant();
    cpm::Writer<VehicleObservation> observations(participant, "vehicleObservation");
    cpm::ReaderAbstract<VehicleObservation> others(participant, "vehicleObservation", {.history_depth = 1});
    std::map<uint8_t, std::pair<uint64_t, cpm::vehicle::Pose>> other_cars;

    const auto physics_period_ns = static_cast<uint64_t>(1e9 / parameters.physics_rate);
    const auto steps_per_state = std::max<uint64_t>(1, std::llround(parameters.physics_rate / parameters.state_rate));
    auto timer = cpm::Timer::create(participant, "firmware_sim_" + std::to_string(vehicle_id), physics_period_ns, 0,
                                    false, false);
    uint64_t last_tick_ns = 0, steps = 0, skipped_steps = 0;
    const uint64_t max_catch_up = std::max<uint64_t>(1, uint64_t(parameters.physics_rate));  // 1 s of model time
    std::pair<cpm::vehicle::MotorMode, uint16_t> traced{cpm::vehicle::MotorMode::Brake, 0};
    auto trace = [&](uint64_t now) {
        auto held = sim.motor_command();
        if (held == traced) return;
        traced = held;
        std::printf("pwm %llu %d %u\n", static_cast<unsigned long long>(now), static_cast<int>(held.first),
                    unsigned(held.second));
        std::fflush(stdout);
    };

    cpm::cli::stop_on_signals();
    timer->start([&](uint64_t t_nominal) {
        if (cpm::cli::stop_requested()) {
            timer->stop();
            return;
        }
        uint8_t buffer[512];
        long n;
        while ((n = read_line(buffer, sizeof buffer)) > 0) {
            sim.receive(buffer, size_t(n));
            if (trace_pwm) trace(cpm::get_time_ns());
        }
        // Catch up on ticks the timer skipped (up to 1 s), so model time keeps pace with real
        // time; but send only one state packet however many fell due: a controller that fell
        // behind must not flood its host (it would only use the newest anyway).
        uint64_t due = last_tick_ns == 0 ? 1 : (t_nominal - last_tick_ns) / physics_period_ns;
        if (due > max_catch_up) {
            skipped_steps += due - max_catch_up;
            due = max_catch_up;
        }
        last_tick_ns = t_nominal;
        bool state_due = false;
        for (uint64_t i = 0; i < due; ++i) {
            sim.step();
            if (++steps % steps_per_state == 0) state_due = true;
        }
        if (!state_due) {
            if (trace_pwm) trace(cpm::get_time_ns());
            return;
        }
        auto frame = cpm::vehicle::encode_frame(sim.make_state_packet());
        if (corrupt_rate > 0 && std::uniform_real_distribution<double>(0, 1)(corruption) < corrupt_rate) {
            frame[corruption() % frame.size()] ^= uint8_t(1 + corruption() % 255);
        }
        write_line(frame);

        uint64_t now = cpm::get_time_ns();
        if (!sim.drop_observation()) {
            VehicleObservation o;
            cpm::stamp_message(o, now, 0);
            o.vehicle_id(vehicle_id);
            auto pose = sim.observed_pose();
            o.pose().x(pose.x);
            o.pose().y(pose.y);
            o.pose().yaw(pose.yaw);
            observations.write(o);
        }
        for (auto& o : others.take()) {
            if (o.vehicle_id() == vehicle_id) continue;
            other_cars[o.vehicle_id()] = {o.header().create_stamp().nanoseconds(), {o.pose().x(), o.pose().y(), o.pose().yaw()}};
        }
        std::vector<cpm::vehicle::Pose> poses;
        for (auto it = other_cars.begin(); it != other_cars.end();) {
            // A car not seen for a second has left the world.
            if (it->second.first + 1'000'000'000ull < now) {
                it = other_cars.erase(it);
            } else {
                poses.push_back(it->second.second);
                ++it;
            }
        }
        sim.set_other_cars(poses);
        if (trace_pwm) trace(cpm::get_time_ns());
    });

    const auto s = sim.stats();
    std::printf("{\"vehicle_id\": %u, \"state_packets\": %llu, \"unanswered_states\": %llu, \"commands\": %llu, "
                "\"wrong_vehicle\": %llu, \"watchdog_stops\": %llu, \"missed_ticks\": %llu, \"model_steps_dropped\": %llu, \"decoder_errors\": {\"oversize\": %llu, "
                "\"bad_cobs\": %llu, \"too_short\": %llu, \"bad_crc\": %llu, \"bad_packet\": %llu}}\n",
                unsigned(vehicle_id), (unsigned long long)s.state_packets, (unsigned long long)s.unanswered_states,
                (unsigned long long)s.commands, (unsigned long long)s.wrong_vehicle, (unsigned long long)s.watchdog_stops,
                (unsigned long long)timer->missed_deadlines(), (unsigned long long)skipped_steps,
                (unsigned long long)s.decoder.oversize,
                (unsigned long long)s.decoder.bad_cobs, (unsigned long long)s.decoder.too_short,
                (unsigned long long)s.decoder.bad_crc, (unsigned long long)s.decoder.bad_packet);
    std::fflush(stdout);
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "firmware_sim", kHelp, run); }
