// A command source in its own process, so that tests can kill it:
//   vehicle_command_writer VEHICLE_ID SPEED CURVATURE  — VehicleCommandSpeedCurvature at 20 Hz until killed.
#include <cpm/CommandLine.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/init.hpp>
#include <cpm/stamp_message.hpp>

#include <VehicleCommandSpeedCurvature.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <string>
#include <thread>
#include <vector>

namespace {

const char* kHelp =
    "usage: vehicle_command_writer VEHICLE_ID SPEED CURVATURE\n"
    "Writes VehicleCommandSpeedCurvature (m/s, 1/m) for the vehicle at 20 Hz until SIGTERM.\n";

int run(int argc, char** argv)
{
    const auto args = cpm::cli::parse_args(std::vector<std::string>(argv + 1, argv + argc), {}, "vehicle_command_writer");
    if (args.positional.size() != 3) throw cpm::cli::UsageError("vehicle_command_writer: give VEHICLE_ID SPEED CURVATURE (see --help)");
    VehicleCommandSpeedCurvature command;
    command.vehicle_id(static_cast<uint8_t>(cpm::cli::parse_integer("VEHICLE_ID", args.positional[0], 1, 255)));
    command.speed(cpm::cli::parse_number("SPEED", args.positional[1], -3, 3));
    command.curvature(cpm::cli::parse_number("CURVATURE", args.positional[2], -10, 10));
    cpm::init(argc, argv);
    cpm::Writer<VehicleCommandSpeedCurvature> writer("vehicleCommandSpeedCurvature");
    std::printf("writing\n");
    std::fflush(stdout);
    static std::atomic<bool> stop{false};
    std::signal(SIGTERM, [](int) { stop = true; });  // a clean exit frees its shared memory
    while (!stop) {
        cpm::stamp_message(command, cpm::get_time_ns(), 0);
        (void)writer.write(command);
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "vehicle_command_writer", kHelp, run); }
