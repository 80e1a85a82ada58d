#include <cpm/routing/RoutingNode.hpp>

#include <cpm/Error.hpp>
#include <cpm/Logging.hpp>
#include <cpm/MultiVehicleReader.hpp>
#include <cpm/Timer.hpp>
#include <cpm/Writer.hpp>
#include <cpm/stamp_message.hpp>

#include <VehicleCommandTrajectory.h>
#include <VehicleState.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <set>

namespace cpm::routing {

struct RoutingNode::Impl
{
    RoutingNodeOptions options;
    Planner planner;
    MultiVehicleReader<VehicleState> states;
    Writer<VehicleCommandTrajectory> trajectories{"vehicleCommandTrajectory"};
    uint64_t t_first = 0;
    std::set<uint8_t> off_graph;  // cars reported as on no lane (reported again once they were placed)
    std::vector<double> plan_ms;
    size_t cycles = 0, overruns = 0, refused_writes = 0;
    double min_distance = std::numeric_limits<double>::infinity();

    Impl(const LaneGraph& graph, RoutingNodeOptions o)
        : options(std::move(o)), planner(graph, options.planner), states("vehicleState", options.vehicle_ids)
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
    for (auto& [id, result] : states.get_samples(t_ns)) {
        const bool fresh = result.valid && result.age_ns <= options.stale_ns;
        if (!fresh) {
            if (planner.has_car(id)) {
                planner.remove_car(id);
                CPM_LOG_WARN("vehicle %u dropped from planning: %s", unsigned(id),
                             result.valid ? ("its state is " + std::to_string(result.age_ns / 1'000'000) + " ms old").c_str()
                                          : "no state");
            }
            continue;
        }
        const auto& s = result.sample;
        const Pose pose{s.pose().x(), s.pose().y(), s.pose().yaw()};
        if (!planner.has_car(id)) {
            try {
                planner.add_car(id, pose, s.speed());
                off_graph.erase(id);
                CPM_LOG_INFO("vehicle %u taken into planning at x %.3f y %.3f yaw %.3f", unsigned(id), pose.x,
                             pose.y, pose.yaw);
            } catch (const cpm::Error& e) {
                if (off_graph.insert(id).second) CPM_LOG_ERROR("%s; not planned until it is on a lane", e.what());
                continue;
            }
        }
        measured.push_back({id, pose, s.speed()});
    }
    const auto t0 = std::chrono::steady_clock::now();
    planner.plan(t, measured);
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    plan_ms.push_back(ms);
    ++cycles;
    for (const auto& w : planner.warnings()) CPM_LOG_WARN("%s", w.c_str());
    for (int id : planner.car_ids()) send(uint8_t(id), t_ns, t);
    const double d = planner.min_planned_distance();
    if (std::isfinite(d)) min_distance = std::min(min_distance, d);
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
    stamp_message(command, t_ns, 0);
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
    auto timer = Timer::create("central_routing", d.options.period_ns, 0,
                               cpm::TimerOptions{.wait_for_start = d.options.wait_for_start, .simulated_time_allowed = true});
    timer->start([&](uint64_t t_nominal) {
        if (stop_requested()) {
            timer->stop();
            return;
        }
        d.cycle(t_nominal);
    });
}

std::string RoutingNode::stats_json() const
{
    const auto& d = *impl_;
    auto sorted = d.plan_ms;
    std::sort(sorted.begin(), sorted.end());
    auto at = [&](double p) { return sorted.empty() ? 0.0 : sorted[std::min(sorted.size() - 1, size_t(p * double(sorted.size() - 1) + 0.5))]; };
    nlohmann::ordered_json j{{"cycles", d.cycles},
                             {"cars_planned", d.planner.car_ids().size()},
                             {"plan_ms_p50", at(0.5)},
                             {"plan_ms_p99", at(0.99)},
                             {"overruns", d.overruns},
                             {"refused_writes", d.refused_writes},
                             {"min_planned_distance_m", std::isfinite(d.min_distance) ? nlohmann::json(d.min_distance) : nlohmann::json()}};
    return j.dump();
}

}  // namespace cpm::routing
