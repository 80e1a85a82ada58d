#include <cpm/routing/Simulate.hpp>

#include <cpm/percentile.hpp>

#include <cpm/Error.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <random>

namespace cpm::routing {
namespace {

double round_to(double v, double unit) { return std::round(v / unit) * unit; }

}  // namespace

std::string SimulationSummary::to_json() const
{
    nlohmann::ordered_json j;
    j["vehicles"] = vehicles;
    j["duration_s"] = round_to(duration_s, 1e-3);
    j["collisions"] = collisions;
    j["min_distance_m"] = std::isfinite(min_distance_m) ? nlohmann::json(round_to(min_distance_m, 1e-4)) : nlohmann::json();
    j["max_wait_s"] = round_to(max_wait_s, 1e-3);
    j["stalled"] = stalled;
    j["distance_m"] = nlohmann::json::array();
    for (double d : distance_m) j["distance_m"].push_back(round_to(d, 1e-3));
    j["throughput_per_min"] = round_to(throughput_per_min, 1e-2);
    j["plan_ms_p50"] = round_to(plan_ms_p50, 1e-3);
    j["plan_ms_p99"] = round_to(plan_ms_p99, 1e-3);
    return j.dump();
}

std::vector<Pose> spread_cars(const ConflictTable& table, size_t n, uint64_t seed, double gap, bool anywhere)
{
    std::vector<uint32_t> candidates;
    for (uint32_t i = 0; i < table.sample_count(); ++i) {
        if (anywhere || table.zone_of(i) < 0) candidates.push_back(i);
    }
    std::vector<bool> taken(table.sample_count(), false);
    std::mt19937_64 rng(seed);
    for (size_t i = candidates.size(); i > 1; --i) std::swap(candidates[i - 1], candidates[size_t(rng() % i)]);
    const auto& o = table.options();
    std::vector<Pose> placed;
    for (uint32_t c : candidates) {
        if (placed.size() == n) break;
        const Pose& p = table.pose(c);
        const auto& near = table.conflicts(c);
        bool free = !taken[c] && std::none_of(near.begin(), near.end(), [&](uint32_t n) { return taken[n]; }) &&
                    std::all_of(placed.begin(), placed.end(),
                                [&](const Pose& q) { return footprint_distance(o.footprint, p, q) >= o.margin + gap; });
        if (!free) continue;
        placed.push_back(p);
        taken[c] = true;
    }
    if (placed.size() < n) {
        throw cpm::Error("only " + std::to_string(placed.size()) + " cars fit on this lane graph outside its conflict zones " +
                         "and clear of each other; asked for " + std::to_string(n));
    }
    return placed;
}

size_t central_zone(const ConflictTable& table)
{
    double x0 = 1e300, y0 = 1e300, x1 = -1e300, y1 = -1e300;
    for (const auto& n : table.graph().nodes) {
        x0 = std::min(x0, n.p.x()), y0 = std::min(y0, n.p.y()), x1 = std::max(x1, n.p.x()), y1 = std::max(y1, n.p.y());
    }
    const Vec2 middle((x0 + x1) / 2, (y0 + y1) / 2);
    size_t best = 0;
    for (size_t z = 0; z < table.zones().size(); ++z) {
        if ((table.zones()[z].centre - middle).norm() < (table.zones()[best].centre - middle).norm()) best = z;
    }
    return best;
}

SimulationSummary simulate(const LaneGraph& graph, const SimulationOptions& options, const std::vector<Pose>& starts)
{
    Planner planner(graph, options.planner);
    const auto poses = starts.empty() ? spread_cars(planner.conflicts(), options.vehicles, options.planner.seed, options.start_gap) : starts;
    for (size_t i = 0; i < poses.size(); ++i) planner.add_car(int(i + 1), poses[i]);
    return simulate(planner, options);
}

SimulationSummary simulate(Planner& planner, const SimulationOptions& options)
{
    const auto ids = planner.car_ids();
    const auto& table = planner.conflicts();
    const Footprint& f = planner.options().footprint;
    SimulationSummary out;
    out.vehicles = ids.size();
    out.duration_s = options.duration;
    out.min_distance_m = std::numeric_limits<double>::infinity();
    // The farthest point of a body from its reference point (the rear axle's centre).
    const double reach = std::max(std::hypot(f.length - f.rear_overhang, f.width / 2), std::hypot(f.rear_overhang, f.width / 2));
    const size_t n = ids.size();
    std::vector<double> start_s(n), standing_since(n, 0), last_s(n), last_v(n, 0);
    std::vector<int> zone(n, -1);
    std::vector<size_t> zone_entries(table.zones().size(), 0);
    std::vector<std::vector<bool>> overlapping(n, std::vector<bool>(n, false));
    for (size_t i = 0; i < n; ++i) start_s[i] = last_s[i] = planner.sample(ids[i], 0).s;
    const size_t samples_per_cycle = size_t(std::llround(options.period / options.sample));
    const size_t cycles = size_t(std::ceil(options.duration / options.period - 1e-9));
    std::vector<PlanSample> now(n);
    std::vector<Pose> poses;  // for options.observe
    for (size_t cycle = 0; cycle < cycles; ++cycle) {
        const double t_cycle = double(cycle) * options.period;
        const auto t0 = std::chrono::steady_clock::now();
        planner.plan(t_cycle);
        out.plan_ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
        // What central_routing would send: points 0.1 s apart from now to the plan's end.
        for (int id : ids) {
            const auto points = planner.trajectory(id, t_cycle, 0.1);
            for (size_t k = 1; k < points.size(); ++k) {
                out.max_point_spacing = std::max(out.max_point_spacing, std::hypot(points[k].x - points[k - 1].x, points[k].y - points[k - 1].y));
            }
            out.max_end_speed = std::max(out.max_end_speed, planner.sample(id, planner.plan_end()).speed);
            const double reach = points.empty() ? 0 : points.back().t - t_cycle;
            out.min_reach_s = cycle == 0 && id == ids.front() ? reach : std::min(out.min_reach_s, reach);
        }
        for (size_t k = 1; k <= samples_per_cycle; ++k) {
            const double t = t_cycle + double(k) * options.sample;
            if (t > options.duration + 1e-9) break;
            for (size_t i = 0; i < n; ++i) {
                now[i] = planner.sample(ids[i], t);
                out.max_speed = std::max(out.max_speed, now[i].speed);
                out.max_acceleration = std::max(out.max_acceleration, std::abs(now[i].speed - last_v[i]) / options.sample);
                if (now[i].speed < 0.01) {
                    out.max_wait_s = std::max(out.max_wait_s, t - standing_since[i]);
                    if (t - standing_since[i] > 10.0 && (out.stall_began_s < 0 || standing_since[i] < out.stall_began_s))
                        out.stall_began_s = standing_since[i];
                } else {
                    standing_since[i] = t;
                }
                last_v[i] = now[i].speed;
                last_s[i] = now[i].s;
                // Entries into conflict zones, by the sample under the car's pose.
                const int z = table.zone_of(table.sample(now[i].edge, now[i].edge_s));
                if (z >= 0 && z != zone[i]) {
                    ++zone_entries[size_t(z)];
                    out.zone_entry_log.emplace_back(t, size_t(z));
                }
                zone[i] = z;
            }
            if (options.observe) {
                poses.clear();
                for (const auto& sample : now) poses.push_back(sample.pose);
                options.observe(t, poses);
            }
            for (size_t i = 0; i < n; ++i) {
                for (size_t j = i + 1; j < n; ++j) {
                    const Pose &a = now[i].pose, &b = now[j].pose;
                    // Bodies at least this far apart: a pair that can neither touch nor come
                    // closer than the closest pair yet is not measured (every pair is, once).
                    const double apart = std::hypot(a.x - b.x, a.y - b.y) - 2 * reach;
                    if (apart > 0 && apart >= out.min_distance_m) {
                        overlapping[i][j] = false;
                        continue;
                    }
                    const double d = footprint_distance(f, a, b);
                    out.min_distance_m = std::min(out.min_distance_m, d);
                    if (d <= 0 && !overlapping[i][j]) ++out.collisions;
                    overlapping[i][j] = d <= 0;
                }
            }
        }
    }
    for (size_t i = 0; i < n; ++i) {
        out.distance_m.push_back(last_s[i] - start_s[i]);
        out.final_poses.emplace_back(ids[i], planner.sample(ids[i], options.duration).pose);
    }
    out.stalled = out.max_wait_s > 10.0;
    out.zone_entries = zone_entries;
    if (!zone_entries.empty()) {
        out.busiest_zone = size_t(std::max_element(zone_entries.begin(), zone_entries.end()) - zone_entries.begin());
        out.throughput_per_min = double(zone_entries[out.busiest_zone]) / (options.duration / 60.0);
    }
    out.plan_ms_p50 = percentile(out.plan_ms, 0.5);
    out.plan_ms_p99 = percentile(out.plan_ms, 0.99);
    double delay = 0;
    const double v_max = planner.options().v_max;
    for (double d : out.distance_m) delay += d > 0 ? options.duration * v_max / d - 1 : 0;
    out.mean_delay = n ? delay / double(n) : 0;
    return out;
}

}  // namespace cpm::routing
