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

namespace {

/// One simulation's running state: what each car did so far and the summary being filled.
class Simulation
{
public:
    Simulation(Planner& planner, const SimulationOptions& options)
        : planner_(planner), options_(options), ids_(planner.car_ids()), table_(planner.conflicts()), f_(planner.options().footprint),
          n_(ids_.size()), start_s_(n_), standing_since_(n_, 0), last_s_(n_), last_v_(n_, 0), zone_(n_, -1),
          zone_entries_(table_.zones().size(), 0), overlapping_(n_, std::vector<bool>(n_, false)), now_(n_)
    {
        out_.vehicles = n_;
        out_.duration_s = options.duration;
        out_.min_distance_m = std::numeric_limits<double>::infinity();
        for (size_t i = 0; i < n_; ++i) start_s_[i] = last_s_[i] = planner.sample(ids_[i], 0).s;
    }

    SimulationSummary run()
    {
        const size_t samples_per_cycle = size_t(std::llround(options_.period / options_.sample));
        const size_t cycles = size_t(std::ceil(options_.duration / options_.period - 1e-9));
        for (size_t cycle = 0; cycle < cycles; ++cycle) {
            const double t_cycle = double(cycle) * options_.period;
            const auto t0 = std::chrono::steady_clock::now();
            planner_.plan(t_cycle);
            out_.plan_ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
            check_trajectories(t_cycle, cycle == 0);
            for (size_t k = 1; k <= samples_per_cycle; ++k) {
                const double t = t_cycle + double(k) * options_.sample;
                if (t > options_.duration + 1e-9) break;
                move_cars(t);
                if (options_.observe) {
                    poses_.clear();
                    for (const auto& sample : now_) poses_.push_back(sample.pose);
                    options_.observe(t, poses_);
                }
                measure_gaps();
            }
        }
        return finish();
    }

private:
    /// What central_routing would send: points 0.1 s apart from now to the plan's end.
    void check_trajectories(double t_cycle, bool first)
    {
        for (int id : ids_) {
            const auto points = planner_.trajectory(id, t_cycle, 0.1);
            for (size_t k = 1; k < points.size(); ++k) {
                out_.max_point_spacing = std::max(out_.max_point_spacing, std::hypot(points[k].x - points[k - 1].x, points[k].y - points[k - 1].y));
            }
            out_.max_end_speed = std::max(out_.max_end_speed, planner_.sample(id, planner_.plan_end()).speed);
            const double ahead = points.empty() ? 0 : points.back().t - t_cycle;
            out_.min_reach_s = first && id == ids_.front() ? ahead : std::min(out_.min_reach_s, ahead);
        }
    }

    /// Every car at time t: its speed and acceleration, how long it stood, the zone it entered.
    void move_cars(double t)
    {
        for (size_t i = 0; i < n_; ++i) {
            now_[i] = planner_.sample(ids_[i], t);
            out_.max_speed = std::max(out_.max_speed, now_[i].speed);
            out_.max_acceleration = std::max(out_.max_acceleration, std::abs(now_[i].speed - last_v_[i]) / options_.sample);
            if (now_[i].speed < 0.01) {
                out_.max_wait_s = std::max(out_.max_wait_s, t - standing_since_[i]);
                if (t - standing_since_[i] > 10.0 && (out_.stall_began_s < 0 || standing_since_[i] < out_.stall_began_s))
                    out_.stall_began_s = standing_since_[i];
            } else {
                standing_since_[i] = t;
            }
            last_v_[i] = now_[i].speed;
            last_s_[i] = now_[i].s;
            // Entries into conflict zones, by the sample under the car's pose.
            const int z = table_.zone_of(table_.sample(now_[i].edge, now_[i].edge_s));
            if (z >= 0 && z != zone_[i]) {
                ++zone_entries_[size_t(z)];
                out_.zone_entry_log.emplace_back(t, size_t(z));
            }
            zone_[i] = z;
        }
    }

    /// The least distance between two bodies now, and the overlaps that began.
    void measure_gaps()
    {
        // The farthest point of a body from its reference point (the rear axle's centre).
        const double reach = std::max(std::hypot(f_.length - f_.rear_overhang, f_.width / 2), std::hypot(f_.rear_overhang, f_.width / 2));
        for (size_t i = 0; i < n_; ++i) {
            for (size_t j = i + 1; j < n_; ++j) {
                const Pose &a = now_[i].pose, &b = now_[j].pose;
                // Bodies at least this far apart: a pair that can neither touch nor come
                // closer than the closest pair yet is not measured (every pair is, once).
                const double apart = std::hypot(a.x - b.x, a.y - b.y) - 2 * reach;
                if (apart > 0 && apart >= out_.min_distance_m) {
                    overlapping_[i][j] = false;
                    continue;
                }
                const double d = footprint_distance(f_, a, b);
                out_.min_distance_m = std::min(out_.min_distance_m, d);
                if (d <= 0 && !overlapping_[i][j]) ++out_.collisions;
                overlapping_[i][j] = d <= 0;
            }
        }
    }

    SimulationSummary finish()
    {
        for (size_t i = 0; i < n_; ++i) {
            out_.distance_m.push_back(last_s_[i] - start_s_[i]);
            out_.final_poses.emplace_back(ids_[i], planner_.sample(ids_[i], options_.duration).pose);
        }
        out_.stalled = out_.max_wait_s > 10.0;
        out_.zone_entries = zone_entries_;
        if (!zone_entries_.empty()) {
            out_.busiest_zone = size_t(std::max_element(zone_entries_.begin(), zone_entries_.end()) - zone_entries_.begin());
            out_.throughput_per_min = double(zone_entries_[out_.busiest_zone]) / (options_.duration / 60.0);
        }
        out_.plan_ms_p50 = percentile(out_.plan_ms, 0.5);
        out_.plan_ms_p99 = percentile(out_.plan_ms, 0.99);
        double delay = 0;
        const double v_max = planner_.options().v_max;
        for (double d : out_.distance_m) delay += d > 0 ? options_.duration * v_max / d - 1 : 0;
        out_.mean_delay = n_ ? delay / double(n_) : 0;
        return std::move(out_);
    }

    Planner& planner_;
    const SimulationOptions& options_;
    const std::vector<int> ids_;
    const ConflictTable& table_;
    const Footprint& f_;
    const size_t n_;
    std::vector<double> start_s_, standing_since_, last_s_, last_v_;
    std::vector<int> zone_;
    std::vector<size_t> zone_entries_;
    std::vector<std::vector<bool>> overlapping_;
    std::vector<PlanSample> now_;
    std::vector<Pose> poses_;  // for options.observe
    SimulationSummary out_;
};

}  // namespace

SimulationSummary simulate(Planner& planner, const SimulationOptions& options) { return Simulation(planner, options).run(); }

}  // namespace cpm::routing
