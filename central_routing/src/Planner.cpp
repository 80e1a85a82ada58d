#include <cpm/routing/Planner.hpp>

#include <cpm/Error.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

namespace cpm::routing {
namespace {

constexpr double kFollowTolerance = 0.10;  // m between a car's measured and planned position
constexpr double kSpeedTolerance = 0.25;   // m/s between its measured and planned speed
constexpr double kMoving = 0.05;           // m/s: a car faster than this drives
constexpr double kForkLook = 1.5;          // m: a standing car may change its way at a fork this near
constexpr double kGoing = 1.0;             // m planned ahead: a car at a fork with this keeps its way
constexpr double kBetter = 0.2;            // m more planned ahead: another way at a fork is better

}  // namespace

std::optional<Mode> mode_from_string(const std::string& name)
{
    if (name == "cooperative") return Mode::cooperative;
    if (name == "cpm_lab") return Mode::cpm_lab;
    return std::nullopt;
}

const char* to_string(Mode mode) { return mode == Mode::cpm_lab ? "cpm_lab" : "cooperative"; }

/// One car: its route (edges with the odometer reading where each starts) and its plan (s and v
/// at the planner's steps from plan_t0).
struct Planner::Car
{
    int id = 0;
    std::mt19937_64 rng;
    std::vector<size_t> route;
    std::vector<double> route_s0;
    bool finite_route = false;  // a goal: the route ends, the car stops at its end
    std::vector<double> ps, pv;  // plan: s and v at plan_t0 + k dt
    double standing_since = 0;   // when the car last stood still (v < 1 cm/s), or NaN while moving
    // This cycle's work:
    std::vector<double> ws;          // window: odometer of each sample ahead
    std::vector<uint32_t> wsample;   // window: the graph sample
    std::vector<uint32_t> at_step;   // the sample the car occupies at each step (current plan)
    std::vector<double> fs, fv;      // fallback: the previous plan, carried to this cycle
    double key = 0;                  // priority: smaller plans first
    bool distrusted = false;         // measured off its plan: the others plan around it braking
    std::vector<uint32_t> braking_at_step;  // where it would be, braking from where it is measured
};

struct Planner::Impl
{
    const LaneGraph& graph;
    PlannerOptions o;
    ConflictTable table;
    std::map<int, Car> cars;
    double t0 = 0;
    size_t steps = 0;  // K: steps 0..K
    double min_distance = std::numeric_limits<double>::infinity();
    ClosestPair closest;
    bool gave_up = false;
    std::vector<std::string> warnings;
    // Scratch for the window lookup, reused across cars.
    std::vector<int32_t> window_head, window_next, marks;
    std::vector<uint8_t> blocked, dilated;
    std::vector<uint8_t> outside_zone;  // per window sample: outside every conflict zone
    std::vector<int> last_blocked;  // per window sample: the last step it is blocked at (-1: never)
    std::vector<size_t> edge_load;  // cars on each edge at the start of the cycle
    std::vector<double> follow_errors;  // |measured - planned| along the route, every measured car and cycle

    Impl(const LaneGraph& g, PlannerOptions options)
        : graph(g), o(options),
          table(g, ConflictOptions{options.footprint, options.margin, 0.04, options.v_max, options.dt})
    {
        steps = size_t(std::llround(o.horizon / o.dt));
        window_head.assign(table.sample_count(), -1);
    }

    double route_length_end(const Car& c) const { return c.route_s0.back() + graph.edges[c.route.back()].length(); }

    size_t route_index(const Car& c, double s) const
    {
        size_t i = size_t(std::upper_bound(c.route_s0.begin(), c.route_s0.end(), s) - c.route_s0.begin());
        return i == 0 ? 0 : i - 1;
    }
    Pose pose_on_route(const Car& c, double s) const
    {
        const size_t i = route_index(c, s);
        return graph.pose_at(c.route[i], s - c.route_s0[i]);
    }

    void extend_route(Car& c, double to_s)
    {
        while (!c.finite_route && route_length_end(c) < to_s) {
            // A random walk that shuns crowded lanes: each way on is drawn with weight
            // 1 / (1 + cars on it and the lanes after it), so traffic spreads over the map
            // instead of filling one loop until it locks.
            const auto& next = graph.successors[c.route.back()];
            std::vector<uint64_t> weight;
            uint64_t total = 0;
            for (size_t e : next) {
                size_t crowd = edge_load.empty() ? 0 : 2 * edge_load[e];
                for (size_t f : graph.successors[e]) crowd += edge_load.empty() ? 0 : edge_load[f];
                weight.push_back(1000 / (1 + crowd));
                total += weight.back();
            }
            uint64_t draw = c.rng() % total;
            size_t pick = next.back();
            for (size_t i = 0; i < next.size(); ++i) {
                if (draw < weight[i]) {
                    pick = next[i];
                    break;
                }
                draw -= weight[i];
            }
            c.route_s0.push_back(route_length_end(c));
            c.route.push_back(pick);
        }
    }

    void drop_passed_edges(Car& c, double s)
    {
        // Keep the edge the car's rear is on and one before it (the window looks a metre back).
        size_t keep = 0;
        while (keep + 2 < c.route.size() && c.route_s0[keep + 2] < s - 1.0) ++keep;
        c.route.erase(c.route.begin(), c.route.begin() + long(keep));
        c.route_s0.erase(c.route_s0.begin(), c.route_s0.begin() + long(keep));
    }

    /// Arc length along the route nearest to a measured pose, searched around the expected s.
    std::optional<double> locate(const Car& c, const Pose& pose, double expected) const
    {
        std::optional<double> best;
        double best_d = 0.3;
        const Vec2 q(pose.x, pose.y);
        for (size_t i = 0; i < c.route.size(); ++i) {
            const auto& e = graph.edges[c.route[i]];
            if (c.route_s0[i] > expected + 1.0 || c.route_s0[i] + e.length() < expected - 1.0) continue;
            for (size_t k = 1; k < e.points.size(); ++k) {
                const Vec2 d = e.points[k] - e.points[k - 1];
                double u = std::clamp((q - e.points[k - 1]).dot(d) / d.squaredNorm(), 0.0, 1.0);
                double dist = (e.points[k - 1] + u * d - q).norm();
                double s = c.route_s0[i] + e.s[k - 1] + u * d.norm();
                if (dist < best_d && std::abs(s - expected) < 1.0) best_d = dist, best = s;
            }
        }
        return best;
    }

    /// The samples ahead of the car (and a metre behind it) in route order.
    void build_window(Car& c, double s0, double reach)
    {
        c.ws.clear();
        c.wsample.clear();
        for (size_t i = 0; i < c.route.size(); ++i) {
            const double start = c.route_s0[i], len = graph.edges[c.route[i]].length();
            if (start + len < s0 - 1.0) continue;
            if (start > s0 + reach) break;
            const size_t e = c.route[i];
            const uint32_t first = table.first_sample(e);
            const double step = table.sample_step(e);
            for (size_t k = i > 0 ? 1 : 0; k < table.samples_on(e); ++k) {  // a lane's first sample is the last one's end
                if (start + double(k) * step < s0 - 1.0) continue;
                c.ws.push_back(start + double(k) * step);
                c.wsample.push_back(first + uint32_t(k));
            }
        }
    }

    /// The route long enough for this cycle from s, and the window over it.
    void route_and_window(Car& c, double s)
    {
        const double reach = o.v_max * o.horizon + o.footprint.length + 1.0;
        extend_route(c, s + reach + 1.0);
        build_window(c, s, reach);
    }

    size_t window_index(const Car& c, double s) const
    {
        size_t i = size_t(std::lower_bound(c.ws.begin(), c.ws.end(), s) - c.ws.begin());
        if (i == c.ws.size()) return c.ws.size() - 1;
        if (i > 0 && s - c.ws[i - 1] < c.ws[i] - s) return i - 1;
        return i;
    }

    void evaluate(const Car& c, double t, double& s, double& v) const
    {
        double u = (t - t0) / o.dt;
        if (c.ps.empty()) return;
        if (u <= 0) {
            s = c.ps.front(), v = c.pv.front();
            return;
        }
        size_t k = size_t(u);
        if (k >= c.ps.size() - 1) {
            s = c.ps.back(), v = c.pv.back();
            return;
        }
        double tau = (u - double(k)) * o.dt;
        double a = (c.pv[k + 1] - c.pv[k]) / o.dt;
        s = c.ps[k] + c.pv[k] * tau + a * tau * tau / 2;
        v = c.pv[k] + a * tau;
    }

    void plan_cycle(double t, const std::vector<CarState>& measured);
    void prepare(Car& c, double t, const CarState* m);
    void mark_blocked(const Car& c, const std::vector<const Car*>& before, const std::vector<const Car*>& after);
    void plan_cooperative(Car& c);
    void try_other_ways(Car& c, const std::vector<const Car*>& before, const std::vector<const Car*>& after);
    void plan_cpm_lab(Car& c);
    /// Standing at s from `step` to the end of the horizon meets no one.
    bool standing_free(const Car& c, size_t step, double s) const
    {
        if (c.finite_route && s > route_length_end(c) - 0.02) return false;
        if (s > c.ws.back()) return false;
        return last_blocked[window_index(c, s)] < int(step);
    }
    bool blocked_at(const Car& c, size_t step, double s) const
    {
        if (c.finite_route && s > route_length_end(c) - 0.02) return true;
        if (s > c.ws.back()) return true;
        return blocked[step * c.ws.size() + window_index(c, s)] != 0;
    }
    void record_steps(Car& c)
    {
        c.at_step.resize(c.ps.size());
        for (size_t k = 0; k < c.ps.size(); ++k) c.at_step[k] = c.wsample[window_index(c, c.ps[k])];
    }
};

void Planner::Impl::prepare(Car& c, double t, const CarState* m)
{
    // Where the car is now: its plan at t, or its measurement projected onto its route.
    double s = 0, v = 0;
    if (!c.ps.empty()) evaluate(c, t, s, v);
    const double s_plan = s;
    const double v_plan = v;
    if (m) {
        if (auto located = locate(c, m->pose, s_plan)) {
            s = *located;
            v = std::clamp(m->speed, 0.0, o.v_max);
            // A car that does not follow its plan (stopped by hand, slipping, held by its
            // controller) cannot be relied on: the others plan around it as if it braked where
            // it is, until it is seen driving as planned again. It is still sent its plan.
            const bool off = c.ps.size() > 1 && (std::abs(s - s_plan) > kFollowTolerance || std::abs(v - v_plan) > kSpeedTolerance);
            if (c.ps.size() > 1) follow_errors.push_back(std::abs(s - s_plan));
            if (off && !c.distrusted) {
                char buf[200];
                std::snprintf(buf, sizeof buf, "vehicle %d: %.2f m and %.2f m/s off its plan; planned around as braking until it follows again",
                              c.id, s - s_plan, v - v_plan);
                warnings.push_back(buf);
            }
            if (off) {
                c.distrusted = true;
            } else if (c.distrusted && v >= kMoving) {
                c.distrusted = false;
                warnings.push_back("vehicle " + std::to_string(c.id) + ": follows its plan again");
            }
            // A car that follows its plan keeps it: planned again from where it was meant to
            // be, not from a few centimetres behind (every real car lags a little, and lag
            // taken on as the new plan piles up cycle by cycle into promises the others rely
            // on and it cannot keep). Its controller closes the gap.
            if (!c.distrusted && c.ps.size() > 1) s = s_plan, v = v_plan;
        } else {
            char buf[200];
            std::snprintf(buf, sizeof buf, "vehicle %d: measured at x %.3f y %.3f yaw %.3f, more than 0.3 m from its route; kept its plan",
                          c.id, m->pose.x, m->pose.y, m->pose.yaw);
            warnings.push_back(buf);
        }
    }
    // The fallback: the previous plan from t on, moved to where the car is, then standing.
    c.fs.assign(steps + 1, 0);
    c.fv.assign(steps + 1, 0);
    for (size_t k = 0; k <= steps; ++k) {
        double fs = s_plan, fv = 0;
        if (!c.ps.empty()) evaluate(c, t + double(k) * o.dt, fs, fv);
        c.fs[k] = fs - s_plan + s;
        c.fv[k] = fv;
    }
    c.fv[0] = v;
    if (c.ps.size() == 1 || c.distrusted) {  // a car that joins (moving or not), or left its plan: brake
        for (size_t k = 1; k <= steps; ++k) {
            c.fv[k] = std::max(0.0, c.fv[k - 1] - o.a_max * o.dt);
            c.fs[k] = c.fs[k - 1] + (c.fv[k - 1] + c.fv[k]) / 2 * o.dt;
        }
    }
    drop_passed_edges(c, s);
    route_and_window(c, s);
    c.ps = c.fs;
    c.pv = c.fv;
    record_steps(c);
    c.braking_at_step = c.at_step;
    // Priority: the earliest it could reach its next conflict zone, less the time it has waited.
    if (v < 0.01) {
        if (std::isnan(c.standing_since)) c.standing_since = t;
    } else {
        c.standing_since = std::numeric_limits<double>::quiet_NaN();
    }
    double to_zone = 1e9;
    for (size_t i = window_index(c, s); i < c.ws.size(); ++i) {
        if (table.zone_of(c.wsample[i]) >= 0) {
            to_zone = std::max(0.0, c.ws[i] - s);
            break;
        }
    }
    const double waited = std::isnan(c.standing_since) ? 0.0 : t - c.standing_since;
    c.key = to_zone / o.v_max - waited;
}

void Planner::Impl::mark_blocked(const Car& c, const std::vector<const Car*>& before, const std::vector<const Car*>& after)
{
    const size_t w = c.ws.size();
    blocked.assign((steps + 1) * w, 0);
    last_blocked.assign(w, -1);  // the last step each sample is blocked at, before the slack below
    window_next.resize(w);
    for (size_t i = 0; i < w; ++i) {
        window_next[i] = window_head[c.wsample[i]];
        window_head[c.wsample[i]] = int32_t(i);
    }
    const size_t here = window_index(c, c.ps[0]);
    const Pose& me = table.pose(c.wsample[here]);
    const double far = 2 * o.v_max * o.horizon + 2 * o.footprint.length + o.margin;
    for (const auto* group : {&before, &after}) {
        for (const Car* other : *group) {
            const Pose& q = table.pose(other->at_step[0]);
            if (std::hypot(q.x - me.x, q.y - me.y) > far) continue;
            // Already too close at the start (a measurement off its plan) and behind this car:
            // where it reaches now, around this car, is ignored (this car may stay or drive
            // away, the one behind must keep back), but not where its plan reaches beyond.
            bool pinned = false, behind = false;
            int32_t reach_now = -1;
            for (uint32_t n : table.conflicts(other->at_step[0])) {
                for (int32_t i = window_head[n]; i >= 0; i = window_next[size_t(i)]) {
                    if (size_t(i) == here) pinned = true;
                    reach_now = std::max(reach_now, i);
                }
            }
            for (int32_t i = window_head[other->at_step[0]]; i >= 0; i = window_next[size_t(i)]) {
                if (size_t(i) < here) behind = true;
            }
            const int32_t ignore_up_to = pinned && behind ? reach_now : -1;
            // A distrusted car planned before this one: both its plan and its braking.
            for (const auto* occupied : {&other->at_step, other->distrusted ? &other->braking_at_step : nullptr}) {
                if (!occupied || occupied->empty()) continue;
                // The window samples one occupied sample blocks, found again only when the
                // sample changes (a standing car occupies the same one step after step).
                uint32_t marked_for = UINT32_MAX;
                for (size_t k = 0; k <= steps; ++k) {
                    const uint32_t sample = (*occupied)[std::min(k, occupied->size() - 1)];
                    if (sample != marked_for) {
                        marks.clear();
                        for (uint32_t n : table.conflicts(sample)) {
                            for (int32_t i = window_head[n]; i >= 0; i = window_next[size_t(i)]) {
                                if (i > ignore_up_to) marks.push_back(i);
                            }
                        }
                        marked_for = sample;
                    }
                    for (int32_t i : marks) {
                        blocked[k * w + size_t(i)] = 1;
                        last_blocked[size_t(i)] = std::max(last_blocked[size_t(i)], int(k));
                    }
                }
            }
        }
    }
    for (size_t i = 0; i < w; ++i) window_head[c.wsample[i]] = -1;
    // Slack in time: a place is blocked from time_slack before another car comes until
    // time_slack after it has gone, so that a car a little late on its plan (real cars lag
    // theirs by a few centimetres) still keeps its distance.
    const size_t slack = size_t(std::llround(o.time_slack / o.dt));
    if (slack > 0) {  // row m: the rows m - slack .. m + slack or-ed (whole rows, which vectorise)
        dilated.assign(blocked.size(), 0);
        for (size_t m = 0; m <= steps; ++m) {
            uint8_t* out = dilated.data() + m * w;
            for (size_t k = m > slack ? m - slack : 0; k <= std::min(steps, m + slack); ++k) {
                const uint8_t* in = blocked.data() + k * w;
                for (size_t i = 0; i < w; ++i) out[i] |= in[i];
            }
        }
        blocked.swap(dilated);
    }
    for (int& last : last_blocked) {
        if (last >= 0) last = int(std::min(steps, size_t(last) + slack));
    }
}

void Planner::Impl::plan_cooperative(Car& c)
{
    const double a = o.a_max, dt = o.dt;
    // A car may come to stand only outside every conflict zone (standing in a crossing it could
    // block the car it waits for), at the end of its route, or where it stands now.
    const double s_start = c.fs[0];
    const size_t w = c.ws.size();
    outside_zone.resize(w);
    for (size_t i = 0; i < w; ++i) outside_zone[i] = table.zone_of(c.wsample[i]) < 0;
    const double route_end = c.finite_route ? route_length_end(c) : std::numeric_limits<double>::infinity();
    // s at window sample i (window_index(c, s) == i).
    auto may_stand_at = [&](double s, size_t i) { return s - s_start < 1e-6 || outside_zone[i] || s > route_end - 0.05; };
    auto may_stand = [&](double s) { return may_stand_at(s, window_index(c, s)); };
    // Where the first conflict zone ahead ends: a car that enters it must be able to leave it.
    double s_exit = s_start;
    {
        size_t i = window_index(c, s_start);
        while (i < c.ws.size() && table.zone_of(c.wsample[i]) < 0) ++i;
        while (i < c.ws.size() && table.zone_of(c.wsample[i]) >= 0) ++i;
        if (i < c.ws.size()) s_exit = c.ws[i];
    }
    // A state (s, v) at step k is safe when one of three ways on from it never meets another car
    // and ends standing where the car may stand, within the horizon: brake now; or hold the
    // speed, or speed up to v_max, until braking would stop it past the zone ahead, then brake.
    // Each is a rule of the state alone, so the next step of a safe way leads to a safe state:
    // the car always has a safe choice.
    enum class Way { brake, hold, go };
    // Beyond the window, or past the end of a finite route: blocked at every step.
    const double last_s = std::min(c.ws.back(), route_end - 0.02);
    auto safe = [&](size_t k, double s, double v, Way way) {
        // s only grows along a way: its window sample is followed forward, as window_index
        // would find it (the nearest, the later one on a tie).
        size_t at = window_index(c, s);
        if (v < 1e-9 && !may_stand_at(s, at)) return false;  // it would stand, even for a moment, in a zone
        const double cruise = way == Way::go ? o.v_max : v;
        bool braking = way == Way::brake;
        for (size_t m = k; m <= steps; ++m) {
            while (at + 1 < w && !(s - c.ws[at] < c.ws[at + 1] - s)) ++at;
            if (v == 0 && braking) return may_stand_at(s, at) && s <= last_s && last_blocked[at] < int(m);  // standing_free
            if (s > last_s || blocked[m * w + at] || m == steps) return false;  // met someone, or still moving at the horizon's end
            if (!braking) {
                // Brake for the first place past the zone where it may stand and no one comes.
                const double stop = s + v * v / (2 * a);
                const size_t arrive = std::min(steps, m + size_t(std::ceil(v / (a * dt))));
                braking = (stop >= s_exit && may_stand(stop) && standing_free(c, arrive, stop)) ||
                          v >= a * double(steps - m) * dt - 1e-9;
            }
            const double v1 = braking ? std::max(0.0, v - a * dt) : std::min(cruise, v + a * dt);
            s += (v + v1) / 2 * dt;
            v = v1;
        }
        return false;
    };
    std::vector<double> ps{c.fs[0]}, pv{c.fv[0]};
    bool on_fallback = true;
    const double candidates[] = {a, a / 2, 0, -a / 2, -a};
    for (size_t k = 0; k < steps; ++k) {
        const double s = ps.back(), v = pv.back();
        bool taken = false;
        for (double acc : candidates) {
            const double v1 = std::clamp(v + acc * dt, 0.0, o.v_max);
            const double s1 = s + (v + v1) / 2 * dt;
            if (safe(k + 1, s1, v1, Way::brake) || safe(k + 1, s1, v1, Way::hold) || safe(k + 1, s1, v1, Way::go)) {
                on_fallback = on_fallback && std::abs(s1 - c.fs[k + 1]) < 1e-9 && std::abs(v1 - c.fv[k + 1]) < 1e-9;
                ps.push_back(s1), pv.push_back(v1), taken = true;
                break;
            }
        }
        if (taken) continue;
        // No safe way on (a car, this one or another, lags its plan): keep to the previous plan,
        // which every other car planned around this cycle; once off it, brake.
        if (on_fallback) {
            ps.push_back(c.fs[k + 1]), pv.push_back(c.fv[k + 1]);
        } else {
            const double v1 = std::max(0.0, v - a * dt);
            ps.push_back(s + (v + v1) / 2 * dt), pv.push_back(v1);
            on_fallback = false;
        }
    }
    c.ps = std::move(ps);
    c.pv = std::move(pv);
}

void Planner::Impl::try_other_ways(Car& c, const std::vector<const Car*>& before, const std::vector<const Car*>& after)
{
    // A car standing at a fork whose drawn way is blocked (a queue on it, or no place to stand
    // past the zone it leads into) takes another way on if that lets it drive: joining the queue
    // it could close a ring of waiting cars that no one leaves. Only while it stands and its
    // previous plan kept it standing, so that what the others planned around it still holds.
    if (c.finite_route || std::isnan(c.standing_since)) return;
    const double s = c.fs[0];
    if (*std::max_element(c.fs.begin(), c.fs.end()) > s + 1e-6) return;
    if (c.ps.back() - s >= kGoing) return;
    size_t fork = 0;
    for (size_t i = 1; i < c.route.size() && fork == 0; ++i) {
        if (c.route_s0[i] < s - table.options().spacing) continue;  // passed (a car at the fork has not chosen)
        if (c.route_s0[i] > s + kForkLook) return;
        if (graph.successors[c.route[i - 1]].size() > 1) fork = i;
    }
    if (fork == 0) return;
    struct Choice { std::vector<size_t> route; std::vector<double> route_s0, ws, ps, pv; std::vector<uint32_t> wsample; };
    auto keep = [&] { return Choice{c.route, c.route_s0, c.ws, c.ps, c.pv, c.wsample}; };
    Choice best = keep();
    double best_ahead = c.ps.back() - s;
    const size_t drawn = c.route[fork];
    for (size_t e : graph.successors[c.route[fork - 1]]) {
        if (e == drawn) continue;
        c.route.resize(fork + 1);
        c.route_s0.resize(fork + 1);
        c.route[fork] = e;
        route_and_window(c, s);
        mark_blocked(c, before, after);
        plan_cooperative(c);
        if (c.ps.back() - s > best_ahead + kBetter) {
            best = keep();
            best_ahead = c.ps.back() - s;
        }
    }
    c.route = std::move(best.route);
    c.route_s0 = std::move(best.route_s0);
    c.ws = std::move(best.ws);
    c.wsample = std::move(best.wsample);
    c.ps = std::move(best.ps);
    c.pv = std::move(best.pv);
}

void Planner::Impl::plan_cpm_lab(Car& c)
{
    // cpm_lab: accelerate to the top speed; where the car would meet a higher-priority one, cap
    // its speed 160 ms (and further back while it is slow) earlier to max(v - 0.3, v_min), with
    // ±a ramps around the cap; a conflict closer than 240 ms cannot be avoided: give up.
    const double dt = o.dt, a = o.a_max;
    const size_t back = std::max<size_t>(1, size_t(std::llround(0.16 / dt)));
    const size_t too_close = size_t(std::llround(0.24 / dt));
    std::vector<double> cap(steps + 1, o.v_max);
    std::vector<double> ps, pv;
    for (int iteration = 0; iteration < 2000; ++iteration) {
        ps.assign(1, c.fs[0]);
        pv.assign(1, c.fv[0]);
        for (size_t k = 0; k < steps; ++k) {
            const double v = pv.back();
            double v1 = std::min({v + a * dt, o.v_max, cap[k + 1]});
            if (v >= o.cpm_lab_v_min) v1 = std::max(v1, o.cpm_lab_v_min);  // never below v_min once moving
            v1 = std::max(v1, v - a * dt);
            pv.push_back(v1);
            ps.push_back(ps.back() + (v + v1) / 2 * dt);
        }
        size_t hit = SIZE_MAX;
        for (size_t k = 0; k <= steps && hit == SIZE_MAX; ++k) {
            if (blocked_at(c, k, ps[k])) hit = k;
        }
        if (hit == SIZE_MAX) break;
        size_t idx = hit >= back ? hit - back : 0;
        while (idx >= back && pv[idx] < o.cpm_lab_v_min + 0.05) idx -= back;
        if (idx < too_close) {
            gave_up = true;
            break;
        }
        const double capped = std::max(pv[idx] - 0.3, o.cpm_lab_v_min);
        for (size_t m = 0; m <= steps; ++m) {
            const double ramp = capped + a * dt * double(m > idx ? m - idx : idx - m);
            cap[m] = std::min(cap[m], ramp);
        }
    }
    c.ps = std::move(ps);
    c.pv = std::move(pv);
}

void Planner::Impl::plan_cycle(double t, const std::vector<CarState>& measured)
{
    warnings.clear();
    edge_load.assign(graph.edges.size(), 0);
    for (auto& [id, c] : cars) {
        double s = c.ps.front(), v = 0;
        if (c.ps.size() > 1) evaluate(c, t, s, v);
        ++edge_load[c.route[route_index(c, s)]];
    }
    std::vector<Car*> order;
    for (auto& [id, c] : cars) {
        const CarState* m = nullptr;
        for (const auto& state : measured) {
            if (state.id == id) m = &state;
        }
        prepare(c, t, m);
        order.push_back(&c);
    }
    t0 = t;
    if (gave_up) {  // cpm_lab's planner stopped: every car brakes and stands
        for (Car* c : order) {
            c->ps.assign(1, c->fs[0]);
            c->pv.assign(1, c->fv[0]);
            for (size_t k = 0; k < steps; ++k) {
                const double v1 = std::max(0.0, c->pv.back() - o.a_max * o.dt);
                c->ps.push_back(c->ps.back() + (c->pv.back() + v1) / 2 * o.dt);
                c->pv.push_back(v1);
            }
        }
        return;
    }
    if (o.mode == Mode::cooperative) {
        std::stable_sort(order.begin(), order.end(), [](const Car* a, const Car* b) {
            if (a->distrusted != b->distrusted) return b->distrusted;  // the distrusted plan last
            return a->key < b->key || (a->key == b->key && a->id < b->id);
        });
    }
    for (size_t i = 0; i < order.size(); ++i) {
        Car& c = *order[i];
        std::vector<const Car*> before(order.begin(), order.begin() + long(i));
        std::vector<const Car*> after;
        if (o.mode == Mode::cooperative) after.assign(order.begin() + long(i) + 1, order.end());
        mark_blocked(c, before, after);
        if (o.mode == Mode::cooperative) {
            plan_cooperative(c);
            try_other_ways(c, before, after);
        } else {
            plan_cpm_lab(c);
        }
        record_steps(c);
    }
    // The smallest distance between two bodies over the new plans' steps.
    min_distance = std::numeric_limits<double>::infinity();
    for (size_t k = 0; k <= steps; ++k) {
        for (size_t i = 0; i < order.size(); ++i) {
            const Pose a = pose_on_route(*order[i], order[i]->ps[k]);
            for (size_t j = i + 1; j < order.size(); ++j) {
                const Pose b = pose_on_route(*order[j], order[j]->ps[k]);
                if (std::hypot(a.x - b.x, a.y - b.y) > 1.0 + o.margin) continue;
                const double d = footprint_distance(o.footprint, a, b);
                if (d < min_distance) {
                    min_distance = d;
                    closest = {order[i]->id, order[j]->id, double(k) * o.dt};
                }
            }
        }
    }
}

Planner::Planner(const LaneGraph& graph, PlannerOptions options) : impl_(std::make_unique<Impl>(graph, options)) {}
Planner::~Planner() = default;

void Planner::add_car(int id, const Pose& pose, double speed)
{
    auto& d = *impl_;
    auto projection = d.graph.project(pose);
    if (!projection) {
        char buf[200];
        std::snprintf(buf, sizeof buf, "vehicle %d at x %.3f y %.3f yaw %.3f is on no lane (none within 0.3 m heading within 0.8 rad)",
                      id, pose.x, pose.y, pose.yaw);
        throw cpm::Error(buf);
    }
    Car c;
    c.id = id;
    c.rng.seed(d.o.seed * 1000003ull + uint64_t(id));
    c.route = {projection->edge};
    c.route_s0 = {0.0};
    c.standing_since = std::numeric_limits<double>::quiet_NaN();
    const double reach = d.o.v_max * d.o.horizon + d.o.footprint.length + 2.0;
    d.extend_route(c, projection->s + reach);
    // Standing where it is until the first cycle plans it (or moving at `speed`: it brakes then).
    c.ps.assign(1, projection->s);
    c.pv.assign(1, std::clamp(speed, 0.0, d.o.v_max));
    d.cars[id] = std::move(c);
}

void Planner::remove_car(int id) { impl_->cars.erase(id); }
bool Planner::has_car(int id) const { return impl_->cars.count(id) > 0; }

std::vector<int> Planner::car_ids() const
{
    std::vector<int> ids;
    for (const auto& [id, c] : impl_->cars) ids.push_back(id);
    return ids;
}

void Planner::set_goal(int id, size_t goal_node)
{
    auto& d = *impl_;
    Car& c = d.cars.at(id);
    double s = c.ps.front(), v = 0;
    if (c.ps.size() > 1) d.evaluate(c, d.t0, s, v);
    // The edge the car is on stays; the shortest path from its end replaces the rest.
    const size_t i = d.route_index(c, s);
    auto path = d.graph.shortest_path(c.route[i], goal_node);
    if (path.empty()) {
        throw cpm::Error("vehicle " + std::to_string(id) + ": node " + std::to_string(d.graph.nodes.at(goal_node).id) +
                         " cannot be reached from where it is");
    }
    c.route.resize(i + 1);
    c.route_s0.resize(i + 1);
    for (size_t k = 1; k < path.size(); ++k) {
        c.route_s0.push_back(d.route_length_end(c));
        c.route.push_back(path[k]);
    }
    c.finite_route = true;
}

void Planner::plan(double t, const std::vector<CarState>& measured) { impl_->plan_cycle(t, measured); }

PlanSample Planner::sample(int id, double t) const
{
    const auto& d = *impl_;
    const Car& c = d.cars.at(id);
    PlanSample out;
    double s = c.ps.front(), v = c.pv.front();
    if (c.ps.size() > 1) d.evaluate(c, t, s, v);
    out.s = s;
    out.speed = v;
    out.pose = d.pose_on_route(c, s);
    const size_t i = d.route_index(c, s);
    out.edge = c.route[i];
    out.edge_s = s - c.route_s0[i];
    return out;
}

std::vector<TrajectorySample> Planner::trajectory(int id, double from, double step) const
{
    std::vector<TrajectorySample> out;
    const double end = plan_end();
    for (size_t k = 0;; ++k) {
        const double t = from + double(k) * step;
        if (t > end + 1e-9) break;
        const auto p = sample(id, t);
        out.push_back({t, p.pose.x, p.pose.y, p.speed * std::cos(p.pose.yaw), p.speed * std::sin(p.pose.yaw)});
    }
    return out;
}

std::vector<double> Planner::take_follow_errors()
{
    std::vector<double> out;
    out.swap(impl_->follow_errors);
    return out;
}

double Planner::plan_start() const { return impl_->t0; }
double Planner::plan_end() const { return impl_->t0 + double(impl_->steps) * impl_->o.dt; }
double Planner::min_planned_distance() const { return impl_->min_distance; }
ClosestPair Planner::closest_pair() const { return impl_->closest; }
bool Planner::gave_up() const { return impl_->gave_up; }
const std::vector<std::string>& Planner::warnings() const { return impl_->warnings; }
const ConflictTable& Planner::conflicts() const { return impl_->table; }
const PlannerOptions& Planner::options() const { return impl_->o; }

}  // namespace cpm::routing
