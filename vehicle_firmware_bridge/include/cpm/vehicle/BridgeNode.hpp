#pragma once
#include <cpm/vehicle/BridgeCore.hpp>
#include <cpm/vehicle/Calibration.hpp>
#include <cpm/vehicle/VehicleModel.hpp>

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace cpm::vehicle {

/// firmware_sim's state period on the lab's simulated clock (50 Hz): the bridge ticks in the step
/// of each state packet (timer_ids::kSimulatedCarOffset_ns), and a state machine that looks at
/// the sensors ticks at the same rate, at the period's start.
inline constexpr uint64_t kSimulatedStatePeriod_ns = 20'000'000;
/// On the lab's simulated clock, how long (real time) the bridge waits for a tick's state packet
/// and the controller for the answer to its last one: a pty hands bytes over asynchronously.
/// Long enough that a loaded machine never decides what the run computes; a side that stays
/// silent this long is not waited for again until it sends once more.
inline constexpr std::chrono::milliseconds kSimulatedPacketWait{1000};

/// What vehicle_bridge is told on its command line.
struct BridgeNodeOptions
{
    uint8_t vehicle_id = 0;
    std::string device;        ///< the serial line (a real car's /dev/ttyACM0, firmware_sim's pty)
    int baud = 115200;
    Calibration calibration;
    Pose start;                ///< the pose estimate before any observation
    /// A line whose state packets all name another vehicle for this many packets in a row
    /// (0.5 s at 50 Hz) belongs to another car: the bridge leaves it and tries again after
    /// `foreign_retry_ms`. Fewer foreign packets among the car's own are ignored (counted).
    int foreign_packets_to_leave = 25;
    int foreign_retry_ms = 1000;
    /// Under --simulated_time: the controller's state period (firmware_sim's 50 Hz). The bridge
    /// then ticks on the lab's clock in the step of each state packet instead of waiting on the line.
    uint64_t simulated_state_period_ns = kSimulatedStatePeriod_ns;
};

/// What a run of the bridge counted; printed as one JSON line when it stops.
struct BridgeNodeStats
{
    unsigned vehicle_id = 0;
    uint64_t cycles = 0, link_losses = 0, superseded_states = 0, foreign_packets = 0, foreign_controller = 0;
    uint64_t controller_reported_bad_crc = 0, decoder_errors = 0;
    uint64_t output_discards = 0;  ///< cycles that dropped a lagging line's queued output first
    /// Simulated time: ticks whose state packet had not come within kSimulatedPacketWait of real
    /// time (the run no longer repeats exactly from there).
    uint64_t missed_ticks = 0;
    double cycle_cpu_us_p50 = 0, cycle_cpu_us_p99 = 0;
    uint64_t anomalies[kAnomalyKinds] = {};
    /// One JSON object: {"vehicle_id": …, "cycles": …, …, "refused_commands": …, …}.
    std::string to_json() const;
};

/// vehicle_bridge's loop: opens the serial line (and reopens it when it comes back), feeds every
/// state packet with the lab's commands for this car through a BridgeCore, answers with the
/// command packet and publishes VehicleState and RangeSensors. Anomalies (refused commands,
/// controller restarts, odometer jumps, implausible battery readings, another car's packets)
/// are logged at most once a second per kind, with a count of the ones held back.
/// Uses the process's default participant (cpm::init first).
///
/// One process can serve many cars (a simulator running many, or a computer wired to several):
/// each car keeps its own line, loop thread, BridgeCore and statistics; they share one reader
/// per command topic and one writer per output topic.
class BridgeNode
{
public:
    explicit BridgeNode(BridgeNodeOptions options);
    /// Several cars, distinct ids; throws cpm::Error naming a repeated id.
    explicit BridgeNode(std::vector<BridgeNodeOptions> cars);
    ~BridgeNode();
    BridgeNode(const BridgeNode&) = delete;
    BridgeNode& operator=(const BridgeNode&) = delete;

    /// The simulated-time timer's node id for `cpm lab clock --nodes`: vehicle_bridge_<first id>.
    static std::string timer_name(uint8_t first_vehicle_id);
    /// Runs until `stop_requested()` is true (asked at least every 200 ms), e.g.
    /// cpm::cli::stop_requested after cpm::cli::stop_on_signals. Under --simulated_time it
    /// follows the lab's clock (a tick per state packet, in the controller's step) until the
    /// clock stops it.
    void run(const std::function<bool()>& stop_requested);
    /// The first car's statistics.
    BridgeNodeStats stats() const;
    /// Every car's, in the order given.
    std::vector<BridgeNodeStats> all_stats() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm::vehicle
