// Drives one car (real or `cpm vehicle sim`) with VehicleCommandSpeedCurvature and prints what
// it reports: pose, speed, battery and its three ultrasonic ranges.
//
//   vehicle_drive --vehicle_id N [--speed 0.5] [--curvature 0] [--seconds 5] [--dds_domain D]
#include <cpm/CommandLine.hpp>
#include <cpm/Reader.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/init.hpp>
#include <cpm/stamp_message.hpp>

#include <RangeSensors.h>
#include <VehicleCommandSpeedCurvature.h>
#include <VehicleState.h>

#include <chrono>
#include <cstdio>
#include <thread>

namespace {

const char* kHelp =
    "usage: vehicle_drive --vehicle_id N [--speed M_PER_S] [--curvature PER_M] [--seconds S] [--dds_domain D]\n"
    "Commands the car at this speed and curvature (20 Hz) and prints its state and ranges 4x a second;\n"
    "then stops commanding, so the car brakes once the last command is 1 s old.\n";

int run(int argc, char** argv)
{
    std::vector<std::string> args(argv + 1, argv + argc);
    {
        auto parsed = cpm::cli::parse_args(
            args, {{"--vehicle_id", true}, {"--speed", true}, {"--curvature", true}, {"--seconds", true}}, "vehicle_drive");
        if (!parsed.has("--vehicle_id")) throw cpm::cli::UsageError("vehicle_drive: --vehicle_id is required");
        auto id = static_cast<uint8_t>(cpm::cli::parse_integer("--vehicle_id", parsed.get("--vehicle_id"), 1, 255));
        double speed = cpm::cli::parse_number("--speed", parsed.get("--speed", "0.5"), -3, 3);
        double curvature = cpm::cli::parse_number("--curvature", parsed.get("--curvature", "0"), -10, 10);
        double seconds = cpm::cli::parse_number("--seconds", parsed.get("--seconds", "5"), 0.1, 3600);
        cpm::init(argc, argv);

        cpm::Writer<VehicleCommandSpeedCurvature> command_writer("vehicleCommandSpeedCurvature");
        cpm::Reader<VehicleState> states("vehicleState", {.vehicle_id = id});
        cpm::Reader<RangeSensors> ranges("rangeSensors", {.vehicle_id = id});
        VehicleCommandSpeedCurvature command;
        command.vehicle_id(id);
        command.speed(speed);
        command.curvature(curvature);

        std::printf("%6s %8s %8s %8s %8s %8s %8s %8s %8s\n", "t [s]", "x [m]", "y [m]", "yaw", "v [m/s]", "front",
                    "left", "right", "batt [V]");
        int reports = 0;
        const auto start = std::chrono::steady_clock::now();
        for (int tick = 1; std::chrono::steady_clock::now() - start < std::chrono::duration<double>(seconds); ++tick) {
            cpm::stamp_message(command, cpm::get_time_ns(), 0);
            if (!command_writer.write(command)) std::fprintf(stderr, "vehicle_drive: a command could not be written\n");
            std::this_thread::sleep_for(std::chrono::milliseconds(50));
            if (tick % 5 != 0) continue;
            uint64_t now = cpm::get_time_ns();
            auto s = states.get_sample(now);
            auto r = ranges.get_sample(now);
            if (!s.valid || !r.valid) continue;
            ++reports;
            std::printf("%6.2f %8.3f %8.3f %8.3f %8.2f %8.3f %8.3f %8.3f %8.2f\n", tick * 0.05, s.sample.pose().x(),
                        s.sample.pose().y(), s.sample.pose().yaw(), s.sample.speed(), r.sample.front(), r.sample.left(),
                        r.sample.right(), s.sample.battery_voltage());
            std::fflush(stdout);
        }
        if (reports == 0) {
            std::fprintf(stderr, "vehicle_drive: no VehicleState/RangeSensors from vehicle %u (is `cpm vehicle sim --id %u` running?)\n",
                         unsigned(id), unsigned(id));
            return 1;
        }
        return 0;
    }
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "vehicle_drive", kHelp, run); }
