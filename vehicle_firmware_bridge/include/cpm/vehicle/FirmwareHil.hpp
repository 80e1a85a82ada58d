#pragma once
#include <cpm/vehicle/FirmwareSim.hpp>
#include <cpm/vehicle/FirmwareSimNode.hpp>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

/// The car's real firmware (firmware/, an ATmega2560 program) run in simavr, hardware in the
/// loop: its serial port is a pseudo-terminal (simavr's uart_pty) that vehicle_bridge opens like
/// a USB serial device, and a model car plays against its pins: the motor PWM (OC4A) and
/// direction (PA0/PA1) and the servo pulse (OC1A) drive the VehicleModel; the model's odometer
/// turns into hall edges on INT4, its battery and motor current into ADC0/ADC1 millivolts, its
/// motion into the registers of an MPU-6050-type IMU on TWI, and the rangers' distances into
/// echo pulses on PB0..PB2 after each trigger on PC0. Pins and scales: firmware/src/board.h.
namespace cpm::vehicle {

/// What firmware_hil is told.
struct FirmwareHilOptions
{
    std::string elf;            ///< the firmware to run (an ELF for the ATmega2560)
    SimulatedCar car;           ///< id (written to the chip's EEPROM), start, noise seed, pty link
    VehicleParameters parameters;
    World world;
    bool trace_pwm = false;     ///< print `pwm T_NS MODE PWM` when the chip's motor outputs change
    double corrupt_rate = 0;    ///< probability of flipping one byte of a state frame on its way out
    /// Where the true pose goes (and the other cars' come from), as FirmwareSimNodeOptions's.
    std::string truth_topic = "vehicleObservation";
};

/// What the run saw of the chip.
struct FirmwareHilStats
{
    uint64_t cycles = 0;            ///< simulated cycles (16 MHz)
    double wall_s = 0;              ///< real time spent running the chip
    uint64_t state_packets = 0;     ///< good state frames the chip sent
    uint64_t watchdog_stops = 0;    ///< state packets that newly reported the watchdog's brake
    uint64_t bad_frames_seen = 0;   ///< state packets that reported a bad command frame (rising edges)
    uint64_t motor_changes = 0;     ///< times the motor outputs changed
    uint64_t wall_collisions = 0;
    uint64_t corrupted_frames = 0;  ///< state frames corrupted on purpose (--corrupt-rate)
    double lag_max_ms = 0;          ///< real time: most the chip fell behind the wall clock
};

/// One simulated ATmega2560 running the firmware, and the car around it. Not thread-safe;
/// everything happens in run_to.
class FirmwareHil
{
public:
    /// Loads the ELF; throws cpm::Error naming the file when it is missing, not an AVR program
    /// or built for another chip.
    explicit FirmwareHil(FirmwareHilOptions options);
    ~FirmwareHil();
    FirmwareHil(const FirmwareHil&) = delete;
    FirmwareHil& operator=(const FirmwareHil&) = delete;

    /// The pty's slave: what vehicle_bridge opens.
    const std::string& device() const;
    /// Simulated time since the chip's reset, ns.
    uint64_t chip_ns() const;
    /// Runs the chip and the car until chip time `t` (ns). Throws cpm::Error when the chip
    /// crashed (an illegal instruction, a jump into nowhere).
    void run_to(uint64_t t);
    /// True when the host's bytes waiting for the chip hold a whole frame (or more).
    bool frame_waiting() const;
    /// True while the chip's output still waits to be written to the pty.
    bool output_pending() const;
    /// Called at every state period (chip time, ns) after the physics stepped.
    void on_state_period(std::function<void(uint64_t chip_ns)> callback);
    /// The car (its model, world, rangers, collisions).
    FirmwareSim& car();
    FirmwareHilStats stats() const;
    /// Remembers how far the chip lagged behind the wall clock (real-time runs).
    void note_lag(double ms);

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

/// firmware_hil's loop: one FirmwareHil stepped by one cpm::Timer, publishing the car's true
/// pose as VehicleObservation, like firmware_sim. Real time: the chip runs paced to the wall
/// clock (every 1 ms it catches up, its lag remembered). Under --simulated_time its timer (node
/// `firmware_sim_<id>`, the car's microcontroller slot) ticks once per state packet: it waits
/// up to 100 ms of real time for the bridge's answer to reach the pty, then runs the chip 20 ms.
/// Prints `device: PATH` first, and one JSON line of statistics at the end.
class FirmwareHilNode
{
public:
    explicit FirmwareHilNode(FirmwareHilOptions options);
    ~FirmwareHilNode();
    FirmwareHilNode(const FirmwareHilNode&) = delete;
    FirmwareHilNode& operator=(const FirmwareHilNode&) = delete;

    const std::string& device() const;
    void run(const std::function<bool()>& stop_requested);
    std::string stats_json() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

/// Throws cpm::Error naming the file when it is missing, not an ELF for the AVR, or built for
/// another chip than the ATmega2560 (avr-gcc's device note).
void check_firmware_elf(const std::string& path);

/// Throws cpm::Error naming the parameter when the model car differs from the car the firmware
/// is built for (firmware/src/board.h: odometer ticks per metre, the rangers' range, the state
/// rate, the watchdog): the chip would measure another car than the one simulated.
void check_firmware_parameters(const VehicleParameters& parameters);

/// The default firmware: share/cpm/firmware/cpm_car.elf beside this program's bin/.
std::string default_firmware_elf();

}  // namespace cpm::vehicle
