// firmware_hil: runs the car's real firmware (an ATmega2560 ELF) in simavr behind a pty, a
// model car on its pins (see README.md).
#include <cpm/CommandLine.hpp>
#include <cpm/Error.hpp>
#include <cpm/init.hpp>
#include <cpm/vehicle/FirmwareHil.hpp>

#include <cstdio>
#include <string>

namespace {

const char* kHelp =
    "usage: firmware_hil [ELF] --vehicle_id N [--map FILE] [--params FILE] [--start X,Y,YAW] [--link PATH]\n"
    "                    [--seed N] [--trace-pwm] [--corrupt-rate P] [--truth_topic T] [--dds_domain N] [--simulated_time]\n"
    "\n"
    "Runs the car's firmware - the very ELF that would be flashed onto the car's ATmega2560 -\n"
    "in the simavr simulator at 16 MHz. Its serial port is a pseudo-terminal, printed first as\n"
    "`device: /dev/pts/K`, that vehicle_bridge opens like the car's USB serial device. A model\n"
    "car plays against the chip's pins: motor PWM and direction, steering servo, hall odometer,\n"
    "battery and current on the ADC, an IMU on I2C, three ultrasonic rangers. The car's true\n"
    "pose goes out as VehicleObservation on 'vehicleObservation' (as firmware_sim's). In real\n"
    "time the chip is paced to the wall clock; with --simulated_time it follows the lab's\n"
    "simulated clock as node firmware_sim_N.\n"
    "\n"
    "  ELF             the firmware (default: share/cpm/firmware/cpm_car.elf of this cpm)\n"
    "  --vehicle_id N  the car's id, written to the chip's EEPROM (1..255)\n"
    "  --map FILE      world of walls (JSON); default: no walls\n"
    "  --params FILE   vehicle parameters (JSON) of the model car\n"
    "  --start X,Y,YAW start pose in metres and radians (default 0,0,0)\n"
    "  --link PATH     also make PATH a symlink to the device\n"
    "  --seed N        noise seed (default: the vehicle id)\n"
    "  --trace-pwm     print `pwm T_NS MODE PWM` whenever the chip's motor outputs change\n"
    "  --corrupt-rate P  flip one byte of a state frame on its way to the bridge with probability P\n"
    "  --truth_topic T   where the true poses go and the other cars' come from (default\n"
    "                  vehicleObservation; vehicleObservationTruth in a lab whose positioning\n"
    "                  system, ips_node, writes vehicleObservation)\n"
    "On SIGINT/SIGTERM it prints one JSON line of statistics (simulated MHz, real-time factor,\n"
    "lag, state packets, watchdog stops) and exits 0. A missing ELF, or one for another chip:\n"
    "exit 2 naming it.\n";

int run(int argc, char** argv)
{
    auto parsed = cpm::cli::parse_args(std::vector<std::string>(argv + 1, argv + argc),
                                       {{"--vehicle_id", true}, {"--map", true}, {"--params", true}, {"--start", true},
                                        {"--link", true}, {"--seed", true}, {"--trace-pwm", false},
                                        {"--corrupt-rate", true}, {"--truth_topic", true}},
                                       "firmware_hil");
    if (parsed.positional.size() > 1)
        throw cpm::cli::UsageError("firmware_hil: one ELF file; '" + parsed.positional[1] + "' is a second");
    if (!parsed.has("--vehicle_id")) throw cpm::cli::UsageError("firmware_hil: --vehicle_id is required");
    const auto ids = cpm::vehicle::parse_vehicle_ids("--vehicle_id", parsed.get("--vehicle_id"));
    if (ids.size() != 1) throw cpm::cli::UsageError("firmware_hil: one chip is one car; --vehicle_id lists " + std::to_string(ids.size()));
    cpm::vehicle::FirmwareHilOptions o;
    o.elf = parsed.positional.empty() ? cpm::vehicle::default_firmware_elf() : parsed.positional[0];
    try {
        cpm::vehicle::check_firmware_elf(o.elf);  // a wrong file is a wrong argument: exit 2
    } catch (const cpm::Error& e) {
        throw cpm::cli::UsageError(e.what());
    }
    if (parsed.has("--params")) {
        o.parameters = cpm::vehicle::VehicleParameters::load(parsed.get("--params"));
        try {
            cpm::vehicle::check_firmware_parameters(o.parameters);
        } catch (const cpm::Error& e) {
            throw cpm::cli::UsageError("firmware_hil: --params " + parsed.get("--params") + ": " +
                                       std::string(e.what()).substr(std::string("firmware_hil: ").size()));
        }
    }
    if (parsed.has("--map")) o.world = cpm::vehicle::World::load(parsed.get("--map"));
    o.car.vehicle_id = ids[0];
    if (parsed.has("--start")) o.car.start = cpm::vehicle::parse_poses("--start", parsed.get("--start"), 1)[0];
    o.car.seed = parsed.has("--seed") ? uint32_t(cpm::cli::parse_integer("--seed", parsed.get("--seed"), 0, UINT32_MAX)) : ids[0];
    o.car.link = parsed.get("--link");
    o.trace_pwm = parsed.has("--trace-pwm");
    o.corrupt_rate = cpm::cli::parse_number("--corrupt-rate", parsed.get("--corrupt-rate", "0"), 0, 1);
    o.truth_topic = parsed.get("--truth_topic", o.truth_topic);
    cpm::init(argc, argv);

    cpm::vehicle::FirmwareHilNode node(std::move(o));
    return cpm::cli::run_node(node);
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "firmware_hil", kHelp, run); }
