// vehicle_bridge: the car's computer between the serial line to its microcontroller and the
// lab's DDS topics (see README.md). The work is cpm::vehicle::BridgeNode's.
#include <cpm/CommandLine.hpp>
#include <cpm/init.hpp>
#include <cpm/vehicle/BridgeNode.hpp>
#include <cpm/vehicle/SerialPort.hpp>

#include <cstdio>

namespace {

const char* kHelp =
    "usage: vehicle_bridge --vehicle_id N[,M,…] --device PATH[,PATH…] [--baud 115200]\n"
    "                      [--calibration FILE] [--start X,Y,YAW[;X,Y,YAW…]] [--dds_domain N]\n"
    "\n"
    "Speaks the serial protocol with vehicle N's microcontroller (real hardware or firmware_sim's\n"
    "pseudo-terminal) and the lab over DDS: every state packet (50 Hz) becomes a VehicleState on\n"
    "'vehicleState' and a RangeSensors on 'rangeSensors'; the answer is the motor and servo\n"
    "command from the freshest command for this car (Direct > SpeedCurvature > Trajectory >\n"
    "PathTracking, fresh = younger than 1 s; none fresh or a StopRequest → brake). A command with\n"
    "a NaN, infinite or out-of-range field is refused (logged) and never reaches a controller.\n"
    "The pose is dead-reckoned from odometer and IMU and corrected by 'vehicleObservation' when\n"
    "present; a controller restart or an impossible odometer step rebases it (logged), a battery\n"
    "reading outside the calibration's range is not published. When the link is lost it stops\n"
    "publishing, logs it and reopens the device when it is back. It holds an exclusive lock on\n"
    "the device; another car's packets are ignored, and a line that only carries another car's\n"
    "is left and retried once a second. Samples are stamped with when the controller measured them.\n"
    "Several ids serve several cars from this one process, car k on the k-th --device (and the\n"
    "k-th --start, separated by ';'); each keeps its own line, loop and statistics.\n"
    "\n"
    "  --calibration FILE  units, limits and controller gains (JSON; see vehicle_firmware_bridge/README.md)\n"
    "  --start X,Y,YAW     initial pose estimate (metres, radians) before any observation\n"
    "On SIGINT/SIGTERM it prints one JSON line of statistics per car and exits 0.\n";

int run(int argc, char** argv)
{
    auto parsed = cpm::cli::parse_flags(
        argc, argv, {{"--vehicle_id", true}, {"--device", true}, {"--baud", true}, {"--calibration", true}, {"--start", true}},
        "vehicle_bridge");
    if (!parsed.has("--vehicle_id")) throw cpm::cli::UsageError("vehicle_bridge: --vehicle_id is required");
    if (!parsed.has("--device")) throw cpm::cli::UsageError("vehicle_bridge: --device is required (e.g. /dev/ttyACM0)");
    const auto ids = cpm::vehicle::parse_vehicle_ids("--vehicle_id", parsed.get("--vehicle_id"));
    const auto devices = cpm::cli::split_list("--device", parsed.get("--device"));
    if (devices.size() != ids.size()) {
        throw cpm::cli::UsageError("vehicle_bridge: --device names " + std::to_string(devices.size()) + " device(s) for " +
                                   std::to_string(ids.size()) + " car(s); give one per --vehicle_id, in the same order");
    }
    const int baud = int(cpm::cli::parse_integer("--baud", parsed.get("--baud", "115200"), 1, 4'000'000));
    const auto calibration = parsed.has("--calibration") ? cpm::vehicle::Calibration::load(parsed.get("--calibration"))
                                                         : cpm::vehicle::Calibration{};
    const auto starts = parsed.has("--start") ? cpm::vehicle::parse_poses("--start", parsed.get("--start"), ids.size())
                                              : std::vector<cpm::vehicle::Pose>(ids.size());
    std::vector<cpm::vehicle::BridgeNodeOptions> cars;
    for (size_t k = 0; k < ids.size(); ++k) {
        try {
            cpm::vehicle::SerialPort::check_baud(baud, devices[k]);
        } catch (const cpm::Error& e) {
            throw cpm::cli::UsageError(std::string("--baud: ") + e.what());
        }
        cars.push_back({.vehicle_id = ids[k], .device = devices[k], .baud = baud, .calibration = calibration, .start = starts[k]});
    }
    cpm::init(argc, argv);

    cpm::vehicle::BridgeNode node(std::move(cars));
    cpm::cli::stop_on_signals();
    node.run(cpm::cli::stop_requested);
    for (const auto& stats : node.all_stats()) std::printf("%s\n", stats.to_json().c_str());
    std::fflush(stdout);
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "vehicle_bridge", kHelp, run); }
