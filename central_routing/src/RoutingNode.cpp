#include <cpm/routing/RoutingNode.hpp>
#include <cpm/routing/Simulate.hpp>

#include <cpm/percentile.hpp>

#include <cpm/Error.hpp>
#include <cpm/Logging.hpp>
#include <cpm/MultiVehicleReader.hpp>
#include <cpm/Timer.hpp>
#include <cpm/init.hpp>
#include <cpm/timer_ids.hpp>
#include <cpm/topics.hpp>
#include <cpm/Writer.hpp>
#include <cpm/stamp_message.hpp>

#include <VehicleCommandTrajectory.h>
#include <VehicleState.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <set>

namespace cpm::routing {
namespace {

constexpr double kStartWait = 3.0;  // s the first plan waits for every listed car

}  // namespace

struct RoutingNode::Impl
{
    RoutingNodeOptions options;
    Planner planner;
    MultiVehicleReader<VehicleState> states;
    Writer<VehicleCommandTrajectory> trajectories{topics::vehicle_command_trajectory.name, topics::vehicle_command_trajectory.writer};
    uint64_t t_first = 0;
    std::set<uint8_t> off_graph;  // cars reported as on no lane (reported again once they were placed)
    std::set<uint8_t> silent;     // planned cars whose state went stale
    std::set<uint8_t> commanded;  // cars sent a trajectory this cycle
    std::map<uint8_t, Pose> last_pose;
    bool started = false, said_waiting = false;
    /// On the simulated clock the planner ticks in the cars' step (kSimulatedCarOffset_ns), so
    /// the clock takes no step for it alone: it reads the cars' states as of a nanosecond before
    /// that step (those the bridge writes in it would be there or not as threads ran), and its
    /// plans are valid a nanosecond after it (the cars take them in their next step, never in it).
    const bool simulated = init_settings().simulated_time;
    std::vector<double> plan_ms, follow_errors;
    size_t cycles = 0, overruns = 0, refused_writes = 0;
    double min_distance = std::numeric_limits<double>::infinity();

    Impl(const LaneGraph& graph, RoutingNodeOptions o)
        : options(std::move(o)), planner(graph, options.planner), states(topics::vehicle_state.name, options.vehicle_ids)
    {
    }

    void cycle(uint64_t t_ns);
    void send(uint8_t id, uint64_t t_ns, double t);
};

void RoutingNode::Impl::cycle(uint64_t t_ns)
{
    if (t_first == 0) t_first = t_ns;
    const double t = double(t_ns - t_first) * 1e-9;
    std::vector<CarState> measured;
    commanded.clear();
    for (auto& [id, result] : states.get_samples(simulated ? timer_ids::simulated_read_before_step(t_ns) : t_ns)) {
        const bool fresh = result.valid && result.age_ns <= options.stale_ns;
        if (!fresh) {
            if (planner.has_car(id)) {
                // Out of planning, but not out of the way: the others keep clear of where it
                // was last seen, as if it stood there.
                if (silent.insert(id).second) {
                    CPM_LOG_WARN("vehicle %u dropped from planning: %s; the others keep clear of where it was last seen", unsigned(id),
                                 result.valid ? ("its state is " + std::to_string(result.age_ns / 1'000'000) + " ms old").c_str()
                                              : "no state");
                }
                measured.push_back({id, last_pose[id], 0.0});
            }
            continue;
        }
        const auto& s = result.sample;
        // Where the car is now: its state moved on by its speed over the state's age.
        const double age = double(result.age_ns) * 1e-9;
        const Pose pose{s.pose().x() + s.speed() * age * std::cos(s.pose().yaw()),
                        s.pose().y() + s.speed() * age * std::sin(s.pose().yaw()), s.pose().yaw()};
        if (!planner.has_car(id)) {
            try {
                planner.add_car(id, pose, s.speed());
                off_graph.erase(id);
                CPM_LOG_INFO("vehicle %u taken into planning at x %.3f y %.3f yaw %.3f", unsigned(id), pose.x, pose.y, pose.yaw);
            } catch (const cpm::Error& e) {
                if (off_graph.insert(id).second) CPM_LOG_ERROR("%s; not planned until it is on a lane", e.what());
                continue;
            }
        } else if (silent.erase(id)) {
            CPM_LOG_INFO("vehicle %u is back: taken into planning again at x %.3f y %.3f yaw %.3f", unsigned(id), pose.x, pose.y, pose.yaw);
        }
        last_pose[id] = pose;
        measured.push_back({id, pose, s.speed()});
        commanded.insert(id);
    }
    // The first plan waits (up to kStartWait) for every listed car: one not yet known could be
    // standing where another is sent.
    if (!started) {
        std::string missing;
        for (uint8_t id : options.vehicle_ids) {
            if (!planner.has_car(id) && !off_graph.count(id)) missing += (missing.empty() ? "" : ", ") + std::to_string(id);
        }
        if (!missing.empty() && t < kStartWait) {
            if (!said_waiting) CPM_LOG_INFO("waiting for vehicle(s) %s before the first plan", missing.c_str());
            said_waiting = true;
            return;
        }
        if (!missing.empty()) CPM_LOG_WARN("no state from vehicle(s) %s after %.0f s; planning the others", missing.c_str(), kStartWait);
        started = true;
    }
    const auto t0 = std::chrono::steady_clock::now();
    planner.plan(t, measured);
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    plan_ms.push_back(ms);
    for (double e : planner.take_follow_errors()) follow_errors.push_back(e);
    ++cycles;
    for (const auto& w : planner.warnings()) CPM_LOG_WARN("%s", w.c_str());
    for (uint8_t id : commanded) send(id, t_ns, t);
    const double d = planner.min_planned_distance();
    if (std::isfinite(d)) min_distance = std::min(min_distance, d);
    if (d < options.planner.margin / 2) {
        const auto pair = planner.closest_pair();
        CPM_LOG_WARN("vehicles %d and %d %.3f m apart %.2f s into the plan (a car off its trajectory?)", pair.a, pair.b, d, pair.after);
    }
    if (ms * 1e6 > double(options.period_ns)) {
        ++overruns;
        CPM_LOG_WARN("planning took %.1f ms, longer than the period of %.0f ms", ms, double(options.period_ns) * 1e-6);
    }
    CPM_LOG_DEBUG("cycle %zu: %zu cars planned in %.2f ms, smallest planned distance %.3f m", cycles,
                  planner.car_ids().size(), ms, std::isfinite(d) ? d : -1.0);
}

void RoutingNode::Impl::send(uint8_t id, uint64_t t_ns, double t)
{
    VehicleCommandTrajectory command;
    stamp_message(command, t_ns, simulated ? 1 : 0);
    command.vehicle_id(id);
    std::vector<TrajectoryPoint> points;
    for (const auto& p : planner.trajectory(id, t, options.trajectory_step)) {
        TrajectoryPoint point;
        point.t().nanoseconds(t_ns + uint64_t(std::llround((p.t - t) * 1e9)));
        point.px(p.x);
        point.py(p.y);
        point.vx(p.vx);
        point.vy(p.vy);
        points.push_back(point);
    }
    command.trajectory_points(std::move(points));
    if (!trajectories.write(command)) {
        ++refused_writes;
        CPM_LOG_WARN("DDS refused vehicle %u's trajectory", unsigned(id));
    }
}

RoutingNode::RoutingNode(const LaneGraph& graph, RoutingNodeOptions options)
    : impl_(std::make_unique<Impl>(graph, std::move(options)))
{
}

RoutingNode::~RoutingNode() = default;

void RoutingNode::run(const std::function<bool()>& stop_requested)
{
    auto& d = *impl_;
    auto timer = Timer::create(timer_ids::central_routing, d.options.period_ns, d.simulated ? timer_ids::kSimulatedCarOffset_ns : 0,
                               cpm::TimerOptions{.wait_for_start = d.options.wait_for_start, .simulated_time_allowed = true});
    timer->run_until(stop_requested, [&](uint64_t t_nominal) { d.cycle(t_nominal); });
}

std::string RoutingNode::stats_json() const
{
    const auto& d = *impl_;
    auto at = [&](double p) { return percentile(d.plan_ms, p); };
    nlohmann::ordered_json j{{"cycles", d.cycles},
                             {"cars_planned", d.planner.car_ids().size()},
                             {"plan_ms_p50", at(0.5)},
                             {"plan_ms_p99", at(0.99)},
                             {"overruns", d.overruns},
                             {"follow_error_m_p50", percentile(d.follow_errors, 0.5)},
                             {"follow_error_m_p99", percentile(d.follow_errors, 0.99)},
                             {"refused_writes", d.refused_writes},
                             {"min_planned_distance_m", std::isfinite(d.min_distance) ? nlohmann::json(d.min_distance) : nlohmann::json()}};
    return j.dump();
}

}  // namespace cpm::routing
