// firmware_sim: plays a car's microcontroller behind a pseudo-terminal (see README.md).
#include <cpm/CommandLine.hpp>
#include <cpm/init.hpp>
#include <cpm/vehicle/FirmwareSimNode.hpp>

#include <cstdio>
#include <string>

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
    "'vehicleObservation' and sees other simulated cars' bodies with its rangers. The car stops\n"
    "against a wall it drives into; each collision is logged (warn) and counted.\n"
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
    auto parsed = cpm::cli::parse_flags(argc, argv,
                                       {{"--vehicle_id", true}, {"--map", true}, {"--params", true}, {"--start", true},
                                        {"--link", true}, {"--seed", true}, {"--trace-pwm", false},
                                        {"--corrupt-rate", true}, {"--device", true}, {"--baud", true}},
                                       "firmware_sim");
    if (!parsed.has("--vehicle_id")) throw cpm::cli::UsageError("firmware_sim: --vehicle_id is required");
    if (parsed.has("--device") && parsed.has("--link"))
        throw cpm::cli::UsageError("firmware_sim: --link names a new pty; it cannot go with --device");
    cpm::vehicle::FirmwareSimNodeOptions o;
    o.vehicle_id = static_cast<uint8_t>(cpm::cli::parse_integer("--vehicle_id", parsed.get("--vehicle_id"), 1, 255));
    if (parsed.has("--params")) o.parameters = cpm::vehicle::VehicleParameters::load(parsed.get("--params"));
    if (parsed.has("--map")) o.world = cpm::vehicle::World::load(parsed.get("--map"));
    if (parsed.has("--start")) o.start = cpm::vehicle::parse_pose("--start", parsed.get("--start"));
    o.seed = static_cast<uint32_t>(cpm::cli::parse_integer("--seed", parsed.get("--seed", std::to_string(o.vehicle_id)), 0, UINT32_MAX));
    o.trace_pwm = parsed.has("--trace-pwm");
    o.corrupt_rate = cpm::cli::parse_number("--corrupt-rate", parsed.get("--corrupt-rate", "0"), 0, 1);
    o.link = parsed.get("--link");
    o.device = parsed.get("--device");
    o.baud = int(cpm::cli::parse_integer("--baud", parsed.get("--baud", "115200"), 1, 4'000'000));
    cpm::init(argc, argv);

    cpm::vehicle::FirmwareSimNode node(std::move(o));
    return cpm::cli::run_node(node);
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "firmware_sim", kHelp, run); }
