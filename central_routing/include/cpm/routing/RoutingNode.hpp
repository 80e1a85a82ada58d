#pragma once
// central_routing's work, as a library: the planner driving many cars over DDS.
#include <cpm/routing/Planner.hpp>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace cpm::routing {

struct RoutingNodeOptions
{
    std::vector<uint8_t> vehicle_ids;
    uint64_t period_ns = 400'000'000;
    uint64_t stale_ns = 1'000'000'000;  ///< a car whose newest state is older leaves the planning
    bool wait_for_start = true;          ///< cpm::Timer: wait for the lab's start signal
    double trajectory_step = 0.1;        ///< s between the points sent
    PlannerOptions planner;
};

/// Reads every car's VehicleState (MultiVehicleReader), places each on the lane graph when it
/// first appears (a car on no lane is logged with its pose and left out, the others go on;
/// the first plan waits up to 3 s for every listed car), replans every period from the
/// measured states (cpm::Timer: synchronised start, simulated time when the lab runs on it)
/// and writes one VehicleCommandTrajectory per car per period reaching to the end of its plan.
/// A car whose state is older than stale_ns is dropped from planning and logged (the others
/// keep clear of where it was last seen), and taken back when it returns. Logs every cycle's
/// planning time and the smallest planned distance (debug level); warns when planning took
/// longer than the period. Uses the process's default participant (cpm::init first).
class RoutingNode
{
public:
    RoutingNode(const LaneGraph& graph, RoutingNodeOptions options);
    ~RoutingNode();
    RoutingNode(const RoutingNode&) = delete;
    RoutingNode& operator=(const RoutingNode&) = delete;

    void run(const std::function<bool()>& stop_requested);
    /// Cycles, cars planned, planning time p50/p99, overruns, smallest planned distance.
    std::string stats_json() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm::routing
