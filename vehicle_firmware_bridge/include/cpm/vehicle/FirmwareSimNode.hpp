#pragma once
#include <cpm/vehicle/FirmwareSim.hpp>

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace cpm::vehicle {

/// One simulated car of a firmware_sim process.
struct SimulatedCar
{
    uint8_t vehicle_id = 0;
    Pose start;
    uint32_t seed = 0;     ///< noise seed
    std::string link;      ///< also make this path a symlink to the car's new pty (empty: none)
};

/// The cars of other processes as their vehicleObservation shows them, for a simulator's rangers:
/// each one's newest pose, forgotten a second after it was last seen (it has left the world).
class OtherCars
{
public:
    /// Takes a car's observation (stamp: its create_stamp).
    void seen(uint8_t vehicle_id, uint64_t stamp_ns, const Pose& pose) { cars_[vehicle_id] = {stamp_ns, pose}; }
    /// The poses seen within the second before `now_ns`, by vehicle id; older ones are dropped.
    std::vector<Pose> current(uint64_t now_ns)
    {
        std::vector<Pose> poses;
        for (auto it = cars_.begin(); it != cars_.end();) {
            if (it->second.first + 1'000'000'000ull < now_ns) {
                it = cars_.erase(it);
            } else {
                poses.push_back(it->second.second);
                ++it;
            }
        }
        return poses;
    }

private:
    std::map<uint8_t, std::pair<uint64_t, Pose>> cars_;
};

/// What firmware_sim is told on its command line.
struct FirmwareSimNodeOptions
{
    std::vector<SimulatedCar> cars;  ///< one or more, distinct ids; each behind a pty of its own
    VehicleParameters parameters;
    World world;
    std::string device;    ///< speak on this existing serial device instead of a new pty (one car only)
    int baud = 115200;     ///< with `device`
    bool trace_pwm = false;     ///< print `pwm T_NS MODE PWM` whenever the held motor command changes (one car only)
    double corrupt_rate = 0;    ///< probability of flipping one byte of a state frame
    /// Where the true poses go (and the other cars' come from): vehicleObservation, or
    /// vehicleObservationTruth in a lab whose positioning system writes vehicleObservation.
    std::string truth_topic = "vehicleObservation";
};

/// firmware_sim's loop: one or many FirmwareSims, each behind its own pseudo-terminal (or one
/// behind a serial device), stepped in real time by one cpm::Timer, publishing the true poses
/// as VehicleObservation. Every car's rangers see the other cars' bodies: those of this
/// process directly, those of other processes through vehicleObservation. A collision with a
/// wall is logged (warn, naming the car, the wall and the pose) and counted. Writes
/// `device: PATH` (one car) or `device ID: PATH` (one line per car), the pwm trace and, at the
/// end, one JSON line of statistics per car to stdout. Uses the process's default participant
/// (cpm::init first).
///
/// Under --simulated_time the timer follows the lab's simulated clock (node id `timer_name`):
/// one tick per state packet, the physics steps in between at once, and before each tick it
/// waits up to 100 ms of real time for every car's host to have answered the last packet, so a
/// run is repeatable and as fast as the machine computes.
class FirmwareSimNode
{
public:
    /// Opens the lines; throws cpm::Error naming the device when it cannot, or the option
    /// that is wrong (no car, a repeated id, a device or pwm trace for more than one car).
    explicit FirmwareSimNode(FirmwareSimNodeOptions options);
    ~FirmwareSimNode();
    FirmwareSimNode(const FirmwareSimNode&) = delete;
    FirmwareSimNode& operator=(const FirmwareSimNode&) = delete;

    /// Each car's id and the device path its host opens (the pty's slave, or `device`).
    std::vector<std::pair<uint8_t, std::string>> devices() const;
    /// The timer's node id for `cpm lab clock --nodes`: firmware_sim_<first car's id>.
    static std::string timer_name(uint8_t first_vehicle_id);
    /// Runs until `stop_requested()` is true (asked every tick) or the lab's clock stops it.
    void run(const std::function<bool()>& stop_requested);
    /// One line per car: {"vehicle_id": …, "state_packets": …, …, "wall_collisions": …, "decoder_errors": {…}}
    std::string stats_json() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm::vehicle
