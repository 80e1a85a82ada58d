#pragma once
#include <cpm/vehicle/FirmwareSim.hpp>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

namespace cpm::vehicle {

/// What firmware_sim is told on its command line.
struct FirmwareSimNodeOptions
{
    uint8_t vehicle_id = 0;
    VehicleParameters parameters;
    World world;
    Pose start;
    uint32_t seed = 0;
    std::string link;      ///< also make this path a symlink to the new pty (empty: none)
    std::string device;    ///< speak on this existing serial device instead of a new pty
    int baud = 115200;     ///< with `device`
    bool trace_pwm = false;     ///< print `pwm T_NS MODE PWM` whenever the held motor command changes
    double corrupt_rate = 0;    ///< probability of flipping one byte of a state frame
};

/// firmware_sim's loop: a FirmwareSim behind a pseudo-terminal (or a serial device), stepped
/// in real time by a cpm::Timer, publishing the true pose as VehicleObservation and seeing
/// other simulated cars' bodies. A collision with a wall is logged (warn, naming the wall and
/// the pose) and counted. Writes `device: PATH`, the pwm trace and, at the end, one JSON line
/// of statistics to stdout. Uses the process's default participant (cpm::init first).
class FirmwareSimNode
{
public:
    /// Opens the line; throws cpm::Error naming the device when it cannot.
    explicit FirmwareSimNode(FirmwareSimNodeOptions options);
    ~FirmwareSimNode();
    FirmwareSimNode(const FirmwareSimNode&) = delete;
    FirmwareSimNode& operator=(const FirmwareSimNode&) = delete;

    /// The device path the host opens (the pty's slave, or `device`).
    const std::string& device_path() const;
    /// Runs until `stop_requested()` is true (asked every physics tick).
    void run(const std::function<bool()>& stop_requested);
    /// {"vehicle_id": …, "state_packets": …, …, "wall_collisions": …, "decoder_errors": {…}}
    std::string stats_json() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm::vehicle
