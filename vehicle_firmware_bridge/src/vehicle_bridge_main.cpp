// vehicle_bridge: the car's computer between the serial line to its microcontroller and the
// lab's DDS topics (see README.md). The work is cpm::vehicle::BridgeNode's.
#include <cpm/CommandLine.hpp>
#include <cpm/init.hpp>
#include <cpm/vehicle/BridgeNode.hpp>
#include <cpm/vehicle/SerialPort.hpp>

#include <cstdio>

namespace {

const char* kHelp =
    "usage: vehicle_bridge --vehicle_id N --device PATH [--baud 115200] [--calibration FILE]\n"
    "                      [--start X,Y,YAW] [--dds_domain N]\n"
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
    "\n"
    "  --calibration FILE  units, limits and controller gains (JSON; see vehicle_firmware_bridge/README.md)\n"
    "  --start X,Y,YAW     initial pose estimate (metres, radians) before any observation\n"
    "On SIGINT/SIGTERM it prints one JSON line of statistics and exits 0.\n";

int run(int argc, char** argv)
{
    auto parsed = cpm::cli::parse_flags(
        argc, argv, {{"--vehicle_id", true}, {"--device", true}, {"--baud", true}, {"--calibration", true}, {"--start", true}},
        "vehicle_bridge");
    if (!parsed.has("--vehicle_id")) throw cpm::cli::UsageError("vehicle_bridge: --vehicle_id is required");
    if (!parsed.has("--device")) throw cpm::cli::UsageError("vehicle_bridge: --device is required (e.g. /dev/ttyACM0)");
    cpm::vehicle::BridgeNodeOptions options;
    options.vehicle_id = static_cast<uint8_t>(cpm::cli::parse_integer("--vehicle_id", parsed.get("--vehicle_id"), 1, 255));
    options.device = parsed.get("--device");
    options.baud = int(cpm::cli::parse_integer("--baud", parsed.get("--baud", "115200"), 1, 4'000'000));
    try {
        cpm::vehicle::SerialPort::check_baud(options.baud, options.device);
    } catch (const cpm::Error& e) {
        throw cpm::cli::UsageError(std::string("--baud: ") + e.what());
    }
    if (parsed.has("--calibration")) options.calibration = cpm::vehicle::Calibration::load(parsed.get("--calibration"));
    if (parsed.has("--start")) options.start = cpm::vehicle::parse_pose("--start", parsed.get("--start"));
    cpm::init(argc, argv);

    cpm::vehicle::BridgeNode node(options);
    cpm::cli::stop_on_signals();
    node.run(cpm::cli::stop_requested);
    std::printf("%s\n", node.stats().to_json().c_str());
    std::fflush(stdout);
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "vehicle_bridge", kHelp, run); }
