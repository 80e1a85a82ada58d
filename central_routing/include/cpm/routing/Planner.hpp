#pragma once
// Plans every car's motion on the lane graph so that no two come closer than the margin, and no
// car waits forever. Each car keeps a route (a seeded random walk, or the shortest path to a goal)
// and gets a speed profile along it, 0 <= v <= v_max, |a| <= a_max, that ends at standstill within
// the horizon. Cycle by cycle, in an order that puts first the car that would reach its next
// conflict zone first (time waited counts as time gained), each car takes the fastest profile
// that still leaves it a safe way to brake, against the new plans of the cars before it and the
// previous plans of the cars after it. Those previous plans were safe together and end at
// standstill, so some safe profile always exists: the planner never gives up.
//
// Mode::cpm_lab reproduces cpm_lab's central routing for comparison: fixed priority by ascending
// vehicle id, lower cars' speed capped (never below 0.5 m/s once moving) where they would meet a
// higher car, and planning abandoned for good when a conflict is less than 240 ms away.
#include <cpm/routing/Conflicts.hpp>

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <vector>

namespace cpm::routing {

enum class Mode { cooperative, cpm_lab };

/// "cooperative" or "cpm_lab"; nullopt for anything else.
std::optional<Mode> mode_from_string(const std::string& name);
const char* to_string(Mode mode);

struct PlannerOptions
{
    Mode mode = Mode::cooperative;
    double v_max = 1.0;      ///< m/s
    double a_max = 0.8;      ///< m/s^2, accelerating and braking
    double horizon = 8.0;    ///< s: every plan ends at standstill within it
    double dt = 0.05;        ///< s between the profile's steps
    double margin = 0.05;    ///< m between the cars' bodies
    double time_slack = 0.1; ///< s between one car leaving a place and another taking it
    Footprint footprint;     ///< the cars' bodies (Footprint::of(vehicle parameters))
    uint64_t seed = 1;       ///< the routes' random walks
    double cpm_lab_v_min = 0.5;  ///< Mode::cpm_lab: the least speed once moving
};

/// A car as measured: where it is and how fast it goes.
struct CarState
{
    int id = 0;
    Pose pose;
    double speed = 0;
};

/// The two cars that come closest in the newest plans, and when (s after the plan's start).
struct ClosestPair
{
    int a = 0, b = 0;
    double after = 0;
};

/// A point of a trajectory as VehicleCommandTrajectory carries it.
struct TrajectorySample
{
    double t = 0;  ///< s, planner time
    double x = 0, y = 0, vx = 0, vy = 0;
};

/// A point of a car's plan at a time: where, heading, speed.
struct PlanSample
{
    Pose pose;
    double speed = 0;
    double s = 0;  ///< distance along its route (the odometer of the plan)
    size_t edge = 0;    ///< the edge it is on
    double edge_s = 0;  ///< and how far along it
};

class Planner
{
public:
    Planner(const LaneGraph& graph, PlannerOptions options);
    ~Planner();
    Planner(const Planner&) = delete;
    Planner& operator=(const Planner&) = delete;

    /// Places a car at its pose on the graph (nearest lane within 0.3 m and 0.8 rad), standing.
    /// Throws cpm::Error naming the car and its pose when no lane matches.
    void add_car(int id, const Pose& pose, double speed = 0);
    void remove_car(int id);
    bool has_car(int id) const;
    std::vector<int> car_ids() const;
    /// From now on, car `id` drives the shortest way to node index `goal_node` and stops there.
    /// Throws cpm::Error when the goal cannot be reached from where the car is.
    void set_goal(int id, size_t goal_node);

    /// One planning cycle at time t (seconds). Cars in `measured` are replanned from their
    /// measured pose and speed; the others from their plan at t (ideal cars).
    void plan(double t, const std::vector<CarState>& measured = {});

    /// A car's plan at time t (held at its ends).
    PlanSample sample(int id, double t) const;
    /// A car's plan as trajectory points every `step` seconds from `from` to the plan's end.
    std::vector<TrajectorySample> trajectory(int id, double from, double step) const;
    /// How far each measured car was from its plan along its route (m), per car and cycle,
    /// since the last call.
    std::vector<double> take_follow_errors();
    /// The time the current plans start at and reach to.
    double plan_start() const;
    double plan_end() const;
    /// The smallest distance between two cars' bodies over the newest plans' steps (m).
    double min_planned_distance() const;
    ClosestPair closest_pair() const;
    /// Mode::cpm_lab: true once the planner gave up (a conflict it could not avoid).
    bool gave_up() const;
    /// Cars whose pose could not be found on their route when replanned; they keep their plan.
    const std::vector<std::string>& warnings() const;
    const ConflictTable& conflicts() const;
    const PlannerOptions& options() const;

    struct Car;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm::routing
