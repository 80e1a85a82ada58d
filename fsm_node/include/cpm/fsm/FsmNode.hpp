#pragma once
// fsm_node's work, as a library: a checked state machine driving one car over DDS.
#include <cpm/fsm/Machine.hpp>

#include <ArucoMarkers.h>
#include <RangeSensors.h>
#include <VehicleState.h>

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace cpm::fsm {

/// The machine's inputs from the car's messages at time t_s (seconds): odometer, heading and
/// speed from the state, the three ranges, and the markers (pose in the car frame) if given.
Inputs inputs_from(const VehicleState& state, const RangeSensors& ranges, const ArucoMarkers* markers, double t_s);

/// What `fsm_node --report` prints at the end: distance, heading change, and per wall-following
/// state the followed range against its clearance.
class RunReport
{
public:
    /// `walls`: state id → (side, clearance) of the states that follow a wall.
    explicit RunReport(std::map<int, std::pair<std::string, double>> walls = {}) : walls_(std::move(walls)) {}
    /// One tick of `state` with these inputs.
    void add(const Inputs& in, int state);
    /// The report's lines, each ending in '\n'.
    std::string text() const;

private:
    bool started_ = false;
    double start_odometer_ = 0, start_yaw_ = 0, odometer_ = 0, yaw_ = 0;
    std::map<int, std::vector<std::pair<double, double>>> ranges_;
    std::map<int, std::pair<std::string, double>> walls_;
};

struct FsmNodeOptions
{
    uint8_t vehicle_id = 0;
    double rate_hz = 80;                  ///< how often it looks for a new RangeSensors sample
    uint64_t max_age_ns = 200'000'000;    ///< older input brakes the car
    /// Tick as soon as a new RangeSensors sample arrives instead of at the timer's next look;
    /// then the timer period (1 / rate_hz) is only the watchdog for missing input. Real time
    /// only (the simulated clock steps timers).
    bool tick_on_sample = false;
};

/// Runs a loaded machine against vehicle N: a cpm::Timer looks for a new RangeSensors sample
/// and ticks the machine once per sample against the newest valid VehicleState and
/// RangeSensors (and ArucoMarkers when present), writes VehicleCommandDirect, publishes
/// FsmStatus on every state change, prints each transition, and brakes the car with a
/// StopRequest in Stop states and on missing or stale input (the reason logged). Uses the
/// process's default participant (cpm::init first).
class FsmNode
{
public:
    /// `machine_json`: the checked machine as JSON (LoadResult::json), for the report's walls.
    FsmNode(FsmNodeOptions options, std::unique_ptr<Machine> machine, const std::string& machine_json);
    ~FsmNode();
    FsmNode(const FsmNode&) = delete;
    FsmNode& operator=(const FsmNode&) = delete;

    /// Runs until `stop_requested()` or the machine stops in a final state; leaves the car braked.
    void run(const std::function<bool()>& stop_requested);
    const Machine& machine() const;
    const RunReport& report() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm::fsm
