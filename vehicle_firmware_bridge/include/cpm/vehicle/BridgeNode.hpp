#pragma once
#include <cpm/vehicle/BridgeCore.hpp>
#include <cpm/vehicle/Calibration.hpp>
#include <cpm/vehicle/VehicleModel.hpp>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

namespace cpm::vehicle {

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
};

/// What a run of the bridge counted; printed as one JSON line when it stops.
struct BridgeNodeStats
{
    unsigned vehicle_id = 0;
    uint64_t cycles = 0, link_losses = 0, superseded_states = 0, foreign_packets = 0, foreign_controller = 0;
    uint64_t controller_reported_bad_crc = 0, decoder_errors = 0;
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
class BridgeNode
{
public:
    explicit BridgeNode(BridgeNodeOptions options);
    ~BridgeNode();
    BridgeNode(const BridgeNode&) = delete;
    BridgeNode& operator=(const BridgeNode&) = delete;

    /// Runs until `stop_requested()` is true (asked at least every 200 ms), e.g.
    /// cpm::cli::stop_requested after cpm::cli::stop_on_signals.
    void run(const std::function<bool()>& stop_requested);
    BridgeNodeStats stats() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm::vehicle
