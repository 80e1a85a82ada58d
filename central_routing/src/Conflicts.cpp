#include <cpm/routing/Conflicts.hpp>

#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <map>
#include <set>
#include <cmath>
#include <numeric>

namespace cpm::routing {
namespace {

using Corners = std::array<Vec2, 4>;

/// A body's corners: `front` and `back` metres ahead of and behind the pose, half_width aside.
Corners corners(const Pose& p, double front, double back, double half_width)
{
    const Vec2 c(p.x, p.y), u(std::cos(p.yaw), std::sin(p.yaw)), n(-u.y(), u.x());
    return {c + front * u + half_width * n, c - back * u + half_width * n, c - back * u - half_width * n,
            c + front * u - half_width * n};
}

double segment_distance(const Vec2& p, const Vec2& a, const Vec2& b)
{
    const Vec2 d = b - a;
    double u = std::clamp((p - a).dot(d) / d.squaredNorm(), 0.0, 1.0);
    return (a + u * d - p).norm();
}

/// True when a separating axis among the two rectangles' edge normals exists.
bool separated(const Corners& a, const Corners& b)
{
    for (const Corners* r : {&a, &b}) {
        for (int i = 0; i < 2; ++i) {
            const Vec2 e = (*r)[i + 1] - (*r)[i];
            const Vec2 axis(-e.y(), e.x());
            double amin = 1e300, amax = -1e300, bmin = 1e300, bmax = -1e300;
            for (const auto& q : a) amin = std::min(amin, axis.dot(q)), amax = std::max(amax, axis.dot(q));
            for (const auto& q : b) bmin = std::min(bmin, axis.dot(q)), bmax = std::max(bmax, axis.dot(q));
            if (amax < bmin || bmax < amin) return true;
        }
    }
    return false;
}

double rectangle_distance(const Corners& a, const Corners& b)
{
    if (!separated(a, b)) return 0;
    double best = 1e300;
    for (int i = 0; i < 4; ++i) {
        for (int j = 0; j < 4; ++j) {
            best = std::min(best, segment_distance(a[i], b[j], b[(j + 1) % 4]));
            best = std::min(best, segment_distance(b[j], a[i], a[(i + 1) % 4]));
        }
    }
    return best;
}

/// True when the two lanes' centre lines cross (not merely touch at a shared node).
bool lanes_cross(const LaneEdge& a, const LaneEdge& b)
{
    auto cross = [](const Vec2& u, const Vec2& v) { return u.x() * v.y() - u.y() * v.x(); };
    for (size_t i = 1; i < a.points.size(); ++i) {
        const Vec2 p = a.points[i - 1], r = a.points[i] - p;
        for (size_t j = 1; j < b.points.size(); ++j) {
            const Vec2 q = b.points[j - 1], s = b.points[j] - q;
            const double d = cross(r, s);
            if (std::abs(d) < 1e-12) continue;
            const double t = cross(q - p, s) / d, u = cross(q - p, r) / d;
            if (t > 1e-6 && t < 1 - 1e-6 && u > 1e-6 && u < 1 - 1e-6) return true;
        }
    }
    return false;
}

struct UnionFind
{
    std::vector<uint32_t> parent;
    explicit UnionFind(size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0u); }
    uint32_t find(uint32_t x)
    {
        while (parent[x] != x) x = parent[x] = parent[parent[x]];
        return x;
    }
    void join(uint32_t a, uint32_t b) { parent[find(a)] = find(b); }
};

}  // namespace

double footprint_distance(const Footprint& f, const Pose& a, const Pose& b)
{
    const double front = f.length - f.rear_overhang;
    return rectangle_distance(corners(a, front, f.rear_overhang, f.width / 2), corners(b, front, f.rear_overhang, f.width / 2));
}

ConflictTable::ConflictTable(const LaneGraph& graph, const ConflictOptions& options) : graph_(&graph), options_(options)
{
    for (size_t e = 0; e < graph.edges.size(); ++e) {
        const double length = graph.edges[e].length();
        const size_t n = std::max<size_t>(1, size_t(std::ceil(length / options.spacing)));
        first_.push_back(pose_.size());
        step_.push_back(length / double(n));
        for (size_t k = 0; k <= n; ++k) {
            pose_.push_back(graph.pose_at(e, length * double(k) / double(n)));
            edge_of_.push_back(e);
        }
    }
    // A sample stands for a car anywhere within half a spacing of it, at any moment within half a
    // time step of the planner's: lengthen the body by both, and widen it a little for the lane's
    // curvature over that stretch.
    const Footprint& f = options.footprint;
    const double stretch = options.v_max * options.dt / 2 + options.spacing / 2;
    const double front = f.length - f.rear_overhang + stretch, back = f.rear_overhang + stretch;
    const double half_width = f.width / 2 + 0.005;
    std::vector<Corners> body(pose_.size());
    for (size_t i = 0; i < pose_.size(); ++i) body[i] = corners(pose_[i], front, back, half_width);
    const double reach = 2 * std::hypot(std::max(front, back), half_width) + options.margin;
    conflicts_.resize(pose_.size());
    for (uint32_t i = 0; i < pose_.size(); ++i) {
        for (uint32_t j = i + 1; j < pose_.size(); ++j) {
            if (std::abs(pose_[i].x - pose_[j].x) > reach || std::abs(pose_[i].y - pose_[j].y) > reach) continue;
            if (rectangle_distance(body[i], body[j]) < options.margin) {
                conflicts_[i].push_back(j);
                conflicts_[j].push_back(i);
            }
        }
    }
    // Zones: where a car's body meets a lane that crosses its own (or crosses the lane before or
    // after it), or the main lane it merges into: two cars standing there could each block the
    // other's way. Lanes side by side (a diverge's first stretch, parallel lanes, the main lane
    // of a merge) and a lane with its continuation conflict too, but make no zone: a car may
    // wait there.
    std::vector<std::vector<bool>> crossing(graph.edges.size(), std::vector<bool>(graph.edges.size(), false));
    for (size_t a = 0; a < graph.edges.size(); ++a) {
        for (size_t b = a + 1; b < graph.edges.size(); ++b) crossing[a][b] = crossing[b][a] = lanes_cross(graph.edges[a], graph.edges[b]);
    }
    // Two lanes near a crossing: they cross, or one crosses the other's next or previous lane (a
    // car at the end of a lane pokes into what its next lane crosses).
    const size_t n_edges = graph.edges.size();
    auto adjacent = [&](size_t a, size_t n) { return graph.edges[n].from == graph.edges[a].to || graph.edges[n].to == graph.edges[a].from; };
    std::vector<std::vector<bool>> near_crossing(n_edges, std::vector<bool>(n_edges, false));
    for (size_t a = 0; a < n_edges; ++a) {
        for (size_t b = 0; b < n_edges; ++b) {
            bool near = crossing[a][b];
            for (size_t n = 0; n < n_edges && !near; ++n) near = (adjacent(a, n) && crossing[n][b]) || (adjacent(b, n) && crossing[a][n]);
            near_crossing[a][b] = near;
        }
    }
    // Of two lanes that merge, the main one is the straighter over its last half metre: a car on
    // it may wait beside the merge (the merging car waits behind the merge, out of its way).
    auto turn_at_end = [&](size_t e) {
        const auto& edge = graph.edges[e];
        const double s_end = edge.length();
        return std::abs(cpm::vehicle::wrap_angle(graph.pose_at(e, s_end).yaw - graph.pose_at(e, std::max(0.0, s_end - 0.5)).yaw));
    };
    auto main_lane = [&](size_t a, size_t b) {
        const double ta = turn_at_end(a), tb = turn_at_end(b);
        return ta < tb - 1e-6 || (std::abs(ta - tb) <= 1e-6 && a < b);
    };
    auto makes_zone = [&](uint32_t i, uint32_t j) {
        const size_t a = edge_of_[i], b = edge_of_[j];
        const auto& ea = graph.edges[a];
        const auto& eb = graph.edges[b];
        if (a == b || ea.to == eb.from || eb.to == ea.from) return false;  // the same lane, or its continuation
        if (ea.to == eb.to) return !main_lane(a, b);  // a merge: the merging lane waits before it
        return bool(near_crossing[a][b]);
    };
    // Each pair of lanes that cross (merge, diverge) gives a region; regions whose centres lie
    // within 0.4 m of each other are one zone (the four crossings of an intersection).
    std::map<std::pair<size_t, size_t>, std::set<uint32_t>> regions;
    for (uint32_t i = 0; i < pose_.size(); ++i) {
        for (uint32_t j : conflicts_[i]) {
            if (makes_zone(i, j)) regions[std::minmax(edge_of_[i], edge_of_[j])].insert(i);
        }
    }
    std::vector<const std::set<uint32_t>*> region_samples;
    std::vector<Vec2> region_centre;
    for (const auto& [edges, samples] : regions) {
        Vec2 sum(0, 0);
        for (uint32_t i : samples) sum += Vec2(pose_[i].x, pose_[i].y);
        region_samples.push_back(&samples);
        region_centre.push_back(sum / double(samples.size()));
    }
    UnionFind sets(region_samples.size());
    for (uint32_t a = 0; a < region_samples.size(); ++a) {
        for (uint32_t b = a + 1; b < region_samples.size(); ++b) {
            if ((region_centre[a] - region_centre[b]).norm() < 0.4) sets.join(a, b);
        }
    }
    zone_of_.assign(pose_.size(), -1);
    std::map<uint32_t, size_t> zone_of_root;
    for (uint32_t r = 0; r < region_samples.size(); ++r) {
        auto [it, added] = zone_of_root.emplace(sets.find(r), zones_.size());
        if (added) zones_.emplace_back();
        auto& zone = zones_[it->second];
        for (uint32_t i : *region_samples[r]) {
            if (zone_of_[i] < 0) zone_of_[i] = int(it->second);
            zone.samples.push_back(i);
        }
    }
    for (auto& z : zones_) {
        std::sort(z.samples.begin(), z.samples.end());
        z.samples.erase(std::unique(z.samples.begin(), z.samples.end()), z.samples.end());
        Vec2 sum(0, 0);
        for (uint32_t i : z.samples) sum += Vec2(pose_[i].x, pose_[i].y);
        z.centre = sum / double(z.samples.size());
    }
}

uint32_t ConflictTable::sample(size_t edge, double s) const
{
    const size_t n = samples_on(edge) - 1;
    const double k = std::round(std::clamp(s, 0.0, graph_->edges[edge].length()) / step_[edge]);
    return uint32_t(first_[edge] + std::min<size_t>(size_t(k), n));
}

size_t ConflictTable::pair_count() const
{
    size_t n = 0;
    for (const auto& c : conflicts_) n += c.size();
    return n / 2;
}

}  // namespace cpm::routing
