// A command source in its own process, so that tests can kill it:
//   vehicle_command_writer VEHICLE_ID SPEED CURVATURE  — VehicleCommandSpeedCurvature at 20 Hz until killed.
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/stamp_message.hpp>

#include <VehicleCommandSpeedCurvature.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <thread>

int main(int argc, char** argv)
{
    if (argc != 4) {
        std::fprintf(stderr, "usage: vehicle_command_writer VEHICLE_ID SPEED CURVATURE\n");
        return 2;
    }
    cpm::Writer<VehicleCommandSpeedCurvature> writer("vehicleCommandSpeedCurvature");
    VehicleCommandSpeedCurvature command;
    command.vehicle_id(static_cast<uint8_t>(std::atoi(argv[1])));
    command.speed(std::atof(argv[2]));
    command.curvature(std::atof(argv[3]));
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
