// firmware_sim: plays a car's microcontroller behind a pseudo-terminal (see README.md).
#include <cpm/CommandLine.hpp>
#include <cpm/init.hpp>
#include <cpm/vehicle/FirmwareSimNode.hpp>

#include <cstdio>
#include <string>

namespace {

const char* kHelp =
    "usage: firmware_sim --vehicle_id N[,M,…] [--map FILE] [--params FILE] [--start X,Y,YAW[;X,Y,YAW…]]\n"
    "                    [--link PATH | --device TTY [--baud B]] [--seed N] [--trace-pwm]\n"
    "                    [--corrupt-rate P] [--truth_topic T] [--dds_domain N]\n"
    "\n"
    "Plays vehicle N's microcontroller: opens a pseudo-terminal, prints its device path as\n"
    "`device: /dev/pts/K` and then speaks the serial protocol on it (state packets at\n"
    "state_rate, commands in; vehicle model at physics_rate; watchdog brakes after 250 ms\n"
    "without a valid command). Publishes the true pose as VehicleObservation on\n"
    "'vehicleObservation' and sees other simulated cars' bodies with its rangers. The car stops\n"
    "against a wall it drives into; each collision is logged (warn) and counted.\n"
    "Several ids (--vehicle_id 1,2,3) run several cars in this one process, each behind a pty of\n"
    "its own (printed as `device ID: PATH`, one line per car), all stepped by one timer; their\n"
    "rangers see each other. --start then gives one pose per car, separated by ';'.\n"
    "\n"
    "  --map FILE      world of walls (JSON; the format: scenarios/README.md); default: no walls\n"
    "  --params FILE   vehicle parameters (JSON; see vehicle_firmware_bridge/README.md)\n"
    "  --start X,Y,YAW start pose in metres and radians (default 0,0,0); one per car\n"
    "  --link PATH     also make PATH a symlink to the device (a stable name across restarts; one car)\n"
    "  --device TTY    speak on this existing serial device instead of a new pty (e.g. one end of\n"
    "                  a null-modem cable to a bridge on another computer; one car); --baud B (115200)\n"
    "  --seed N        noise seed (default: the vehicle id); the k-th car (from 0) gets N + k\n"
    "  --trace-pwm     (one car) print `pwm T_NS MODE PWM` on stdout whenever the motor command the controller\n"
    "                  holds changes (a new command, or the watchdog's brake; MODE 0 brake, 1 fwd, 2 rev)\n"
    "  --corrupt-rate P  flip one random byte in a state frame with probability P (tests the link)\n"
    "  --truth_topic T   where the true poses go and the other cars' come from (default\n"
    "                  vehicleObservation; vehicleObservationTruth in a lab whose positioning\n"
    "                  system, ips_node, writes vehicleObservation)\n"
    "On SIGINT/SIGTERM it prints one JSON line of statistics per car and exits 0.\n";

int run(int argc, char** argv)
{
    auto parsed = cpm::cli::parse_flags(argc, argv,
                                       {{"--vehicle_id", true}, {"--map", true}, {"--params", true}, {"--start", true},
                                        {"--link", true}, {"--seed", true}, {"--trace-pwm", false},
                                        {"--corrupt-rate", true}, {"--device", true}, {"--baud", true}, {"--truth_topic", true}},
                                       "firmware_sim");
    if (!parsed.has("--vehicle_id")) throw cpm::cli::UsageError("firmware_sim: --vehicle_id is required");
    if (parsed.has("--device") && parsed.has("--link"))
        throw cpm::cli::UsageError("firmware_sim: --link names a new pty; it cannot go with --device");
    cpm::vehicle::FirmwareSimNodeOptions o;
    const auto ids = cpm::vehicle::parse_vehicle_ids("--vehicle_id", parsed.get("--vehicle_id"));
    if (ids.size() > 1) {
        for (const char* one_car : {"--link", "--device", "--trace-pwm"}) {
            if (parsed.has(one_car))
                throw cpm::cli::UsageError(std::string("firmware_sim: ") + one_car + " is for one car; --vehicle_id lists " +
                                           std::to_string(ids.size()));
        }
    }
    if (parsed.has("--params")) o.parameters = cpm::vehicle::VehicleParameters::load(parsed.get("--params"));
    if (parsed.has("--map")) o.world = cpm::vehicle::World::load(parsed.get("--map"));
    const auto starts = parsed.has("--start") ? cpm::vehicle::parse_poses("--start", parsed.get("--start"), ids.size())
                                              : std::vector<cpm::vehicle::Pose>(ids.size());
    const bool seeded = parsed.has("--seed");
    const auto seed = seeded ? cpm::cli::parse_integer("--seed", parsed.get("--seed"), 0, UINT32_MAX) : 0;
    for (size_t k = 0; k < ids.size(); ++k) {
        o.cars.push_back({.vehicle_id = ids[k], .start = starts[k],
                          .seed = uint32_t(seeded ? uint64_t(seed) + k : ids[k]), .link = parsed.get("--link")});
    }
    o.trace_pwm = parsed.has("--trace-pwm");
    o.corrupt_rate = cpm::cli::parse_number("--corrupt-rate", parsed.get("--corrupt-rate", "0"), 0, 1);
    o.device = parsed.get("--device");
    o.truth_topic = parsed.get("--truth_topic", o.truth_topic);
    o.baud = int(cpm::cli::parse_integer("--baud", parsed.get("--baud", "115200"), 1, 4'000'000));
    cpm::init(argc, argv);

    cpm::vehicle::FirmwareSimNode node(std::move(o));
    return cpm::cli::run_node(node);
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "firmware_sim", kHelp, run); }
