#pragma once
// The planner against ideal cars that follow their plans exactly: no DDS, as fast as it runs.
// What `cpm routing simulate` prints, and what the tests and the benchmark measure.
#include <cpm/routing/Planner.hpp>

#include <functional>
#include <string>
#include <utility>
#include <vector>

namespace cpm::routing {

struct SimulationOptions
{
    size_t vehicles = 4;
    double duration = 60;     ///< s of simulated time
    double period = 0.4;      ///< s between planning cycles
    double sample = 0.02;     ///< s between the distance checks
    double start_gap = 0.1;   ///< m between the cars' bodies at the start, beyond the margin
    /// Its seed also places the cars. No time slack: ideal cars keep their plans to the
    /// microsecond, and the slack is for real cars' lag.
    PlannerOptions planner = ideal_cars();
    /// Sees every car's pose (id order) at every sample, with its time: for a referee of the
    /// tests' own (the distances above are the planner's own footprint_distance).
    std::function<void(double t, const std::vector<Pose>& poses)> observe;

    static PlannerOptions ideal_cars()
    {
        PlannerOptions o;
        o.time_slack = 0;
        return o;
    }
};

struct SimulationSummary
{
    size_t vehicles = 0;
    double duration_s = 0;
    size_t collisions = 0;        ///< times two bodies began to overlap
    double min_distance_m = 0;    ///< between any two bodies at any sample
    double max_wait_s = 0;        ///< the longest any car stood still
    bool stalled = false;         ///< a car stood still for more than 10 s
    double stall_began_s = -1;    ///< when the first standstill that grew over 10 s began (-1: none)
    std::vector<double> distance_m;  ///< per car, in id order
    double throughput_per_min = 0;   ///< cars into the busiest conflict zone per minute
    double plan_ms_p50 = 0, plan_ms_p99 = 0;
    // Beyond the printed line, for tests and benchmarks:
    double max_speed = 0, max_acceleration = 0;  ///< over every car's plan at every sample
    double max_point_spacing = 0;  ///< m between the trajectory points sent (0.1 s apart)
    double min_reach_s = 0;        ///< the least time ahead a sent trajectory covered
    double max_end_speed = 0;      ///< m/s: the fastest any plan was at its horizon's end (every plan ends standing: 0)
    double mean_delay = 0;        ///< time taken over free-flow time at v_max, less one, mean over cars
    size_t busiest_zone = 0;
    std::vector<size_t> zone_entries;  ///< cars into each conflict zone (ConflictTable::zones order)
    std::vector<std::pair<double, size_t>> zone_entry_log;  ///< every entry: (s, zone)
    std::vector<double> plan_ms;  ///< every cycle's planning time
    std::vector<std::pair<int, Pose>> final_poses;  ///< every car (id, pose) at the end

    /// One JSON object in one line, the fields `cpm routing simulate --json` prints.
    std::string to_json() const;
};

/// Start poses for n cars on the graph: outside the conflict zones, their bodies at least the
/// margin and `gap` apart, chosen by the seed. Throws cpm::Error when n cars do not fit.
/// With `anywhere`, zones too (for loads the map cannot hold outside them).
std::vector<Pose> spread_cars(const ConflictTable& table, size_t n, uint64_t seed, double gap = 0.1, bool anywhere = false);

/// The conflict zone nearest the middle of the map (the central intersection of a lab map).
size_t central_zone(const ConflictTable& table);

/// Places the cars (ids 1..n, at spread_cars unless `starts` gives their poses) and runs.
SimulationSummary simulate(const LaneGraph& graph, const SimulationOptions& options, const std::vector<Pose>& starts = {});

/// The same loop on a planner the caller set up (its cars placed, goals set): for tests that
/// build their own situations.
SimulationSummary simulate(Planner& planner, const SimulationOptions& options);

}  // namespace cpm::routing
