#include <cpm/routing/LaneGraph.hpp>

#include <cpm/Error.hpp>
#include <cpm/checkers/JsonChecker.hpp>
#include <cpm/read_text_file.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <queue>
#include <set>

namespace cpm::routing {
namespace {

using json = nlohmann::json;

constexpr double kEndTolerance = 0.01;   // m: an edge's ends must meet its nodes this closely
constexpr double kMaxSpacing = 0.05;     // m between consecutive points

/// Collects errors as `SOURCE: PATH: message`.
struct Checker : checkers::JsonChecker
{
    using JsonChecker::JsonChecker;
    bool number(const json& parent, const std::string& path, const char* key, double& out)
    {
        const auto v = number_member(parent, path, key);
        if (v) out = *v;
        return v.has_value();
    }
};

std::string fmt(double v)
{
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.3f", v);
    return buf;
}

/// Node indices reachable from `start` along edges.
std::vector<bool> reachable(const LaneGraph& g, size_t start)
{
    std::vector<bool> seen(g.nodes.size(), false);
    std::vector<size_t> stack{start};
    seen[start] = true;
    std::vector<std::vector<size_t>> out(g.nodes.size());
    for (const auto& e : g.edges) out[e.from].push_back(e.to);
    while (!stack.empty()) {
        size_t n = stack.back();
        stack.pop_back();
        for (size_t m : out[n]) {
            if (!seen[m]) seen[m] = true, stack.push_back(m);
        }
    }
    return seen;
}

void check_topology(const LaneGraph& g, const json& doc, Checker& c)
{
    std::vector<size_t> out_degree(g.nodes.size(), 0);
    for (const auto& e : g.edges) ++out_degree[e.from];
    for (size_t i = 0; i < g.nodes.size(); ++i) {
        if (out_degree[i] == 0) {
            c.error("$.nodes[" + std::to_string(i) + "]", "node " + std::to_string(g.nodes[i].id) + " has no way out (no edge leaves it)");
        }
    }
    std::map<size_t, std::vector<bool>> from_node;
    for (size_t i = 0; i < g.edges.size(); ++i) {
        const auto& e = g.edges[i];
        auto it = from_node.find(e.to);
        if (it == from_node.end()) it = from_node.emplace(e.to, reachable(g, e.to)).first;
        if (!it->second[e.from]) {
            c.error("$.edges[" + std::to_string(i) + "]", "edge " + doc["edges"][i]["from"].dump() + " -> " +
                                                            doc["edges"][i]["to"].dump() +
                                                            " lies on no cycle: a car that takes it can never come back");
        }
    }
}

}  // namespace

GraphLoad parse_lane_graph(const std::string& json_text, const std::string& source)
{
    Checker c(source);
    const json doc = c.parse(json_text).value_or(json());
    if (!c.ok() || !c.object(doc, "$", "an object with lane_width, nodes and edges")) return c.result<LaneGraph>(std::nullopt);
    c.keys(doc, "$", {"lane_width", "nodes", "edges"});
    LaneGraph g;
    if (c.number(doc, "$", "lane_width", g.lane_width) && g.lane_width <= 0) {
        c.error("$.lane_width", "must be positive, got " + doc["lane_width"].dump());
    }
    std::map<int, size_t> index_of;
    if (!doc.contains("nodes") || !doc["nodes"].is_array() || doc["nodes"].empty()) {
        c.error("$.nodes", "expected a non-empty array of nodes");
    } else {
        for (size_t i = 0; i < doc["nodes"].size(); ++i) {
            const json& n = doc["nodes"][i];
            const std::string path = "$.nodes[" + std::to_string(i) + "]";
            if (!n.is_object()) {
                c.error(path, "expected {\"id\", \"x\", \"y\", \"yaw\"}");
                continue;
            }
            c.keys(n, path, {"id", "x", "y", "yaw"});
            LaneNode node;
            const bool id_ok = n.contains("id") && n["id"].is_number_integer() && n["id"].get<int64_t>() >= std::numeric_limits<int>::min() &&
                               n["id"].get<int64_t>() <= std::numeric_limits<int>::max();
            if (!id_ok) {
                c.error(path + ".id", "expected an integer id that fits in 32 bits");
            } else {
                node.id = n["id"].get<int>();
                if (!index_of.emplace(node.id, i).second) {
                    c.error(path + ".id", "node id " + std::to_string(node.id) + " is used twice (first at $.nodes[" +
                                              std::to_string(index_of[node.id]) + "])");
                }
            }
            c.number(n, path, "x", node.p.x());
            c.number(n, path, "y", node.p.y());
            c.number(n, path, "yaw", node.yaw);
            g.nodes.push_back(node);
        }
    }
    if (!doc.contains("edges") || !doc["edges"].is_array() || doc["edges"].empty()) {
        c.error("$.edges", "expected a non-empty array of edges");
    } else {
        for (size_t i = 0; i < doc["edges"].size(); ++i) {
            const json& e = doc["edges"][i];
            const std::string path = "$.edges[" + std::to_string(i) + "]";
            if (!e.is_object()) {
                c.error(path, "expected {\"from\", \"to\", \"points\"}");
                continue;
            }
            c.keys(e, path, {"from", "to", "points"});
            LaneEdge edge;
            bool ends_known = true;
            for (const char* end : {"from", "to"}) {
                if (!e.contains(end) || !e[end].is_number_integer()) {
                    c.error(path + "." + end, "expected a node id");
                    ends_known = false;
                    continue;
                }
                auto it = index_of.find(e[end].get<int>());
                if (it == index_of.end()) {
                    c.error(path + "." + end, "node " + e[end].dump() + " does not exist");
                    ends_known = false;
                    continue;
                }
                (std::string(end) == "from" ? edge.from : edge.to) = it->second;
            }
            if (!e.contains("points") || !e["points"].is_array() || e["points"].size() < 2) {
                c.error(path + ".points", "expected at least two points [x, y]");
                g.edges.push_back(edge);
                continue;
            }
            bool points_ok = true;
            for (size_t k = 0; k < e["points"].size(); ++k) {
                const json& p = e["points"][k];
                const std::string at = path + ".points[" + std::to_string(k) + "]";
                if (!p.is_array() || p.size() != 2 || !p[0].is_number() || !p[1].is_number() ||
                    !std::isfinite(p[0].get<double>()) || !std::isfinite(p[1].get<double>())) {
                    c.error(at, "expected [x, y] in metres, got " + p.dump());
                    points_ok = false;
                    continue;
                }
                Vec2 q(p[0].get<double>(), p[1].get<double>());
                if (!edge.points.empty()) {
                    double d = (q - edge.points.back()).norm();
                    if (d > kMaxSpacing + 1e-9) {
                        c.error(at, fmt(d) + " m from the point before it (at most 0.05 m apart)");
                    } else if (d < 1e-6) {
                        c.error(at, "repeats the point before it");
                    }
                }
                edge.points.push_back(q);
            }
            if (points_ok && ends_known && !g.nodes.empty()) {
                double d0 = (edge.points.front() - g.nodes[edge.from].p).norm();
                double d1 = (edge.points.back() - g.nodes[edge.to].p).norm();
                if (d0 > kEndTolerance) {
                    c.error(path + ".points[0]", "starts " + fmt(d0) + " m from its node " + e["from"].dump() + " (at most 0.01 m)");
                }
                if (d1 > kEndTolerance) {
                    c.error(path + ".points[" + std::to_string(edge.points.size() - 1) + "]",
                            "ends " + fmt(d1) + " m from its node " + e["to"].dump() + " (at most 0.01 m)");
                }
            }
            edge.s.assign(edge.points.size(), 0.0);
            for (size_t k = 1; k < edge.points.size(); ++k) edge.s[k] = edge.s[k - 1] + (edge.points[k] - edge.points[k - 1]).norm();
            g.edges.push_back(edge);
        }
    }
    if (c.ok()) check_topology(g, doc, c);
    if (!c.ok()) return c.result<LaneGraph>(std::nullopt);
    g.successors.resize(g.edges.size());
    for (size_t i = 0; i < g.edges.size(); ++i) {
        for (size_t j = 0; j < g.edges.size(); ++j) {
            if (g.edges[j].from == g.edges[i].to) g.successors[i].push_back(j);
        }
    }
    return c.result<LaneGraph>(std::move(g));
}

GraphLoad load_lane_graph(const std::string& path)
{
    std::string text;
    try {
        text = cpm::read_text_file(path, "lane graph");
    } catch (const cpm::Error& e) {
        GraphLoad failed;
        failed.errors.push_back({"", e.what()});
        return failed;
    }
    return parse_lane_graph(text, path);
}

LaneGraph load_lane_graph_or_throw(const std::string& path)
{
    return load_lane_graph(path).take_or_throw();
}

Pose LaneGraph::pose_at(size_t edge, double s) const
{
    const auto& e = edges.at(edge);
    s = std::clamp(s, 0.0, e.length());
    size_t k = size_t(std::upper_bound(e.s.begin(), e.s.end(), s) - e.s.begin());
    k = std::clamp<size_t>(k, 1, e.points.size() - 1);
    const Vec2& a = e.points[k - 1];
    const Vec2& b = e.points[k];
    double seg = e.s[k] - e.s[k - 1];
    double u = seg > 0 ? (s - e.s[k - 1]) / seg : 0;
    Vec2 p = a + u * (b - a);
    return Pose{p.x(), p.y(), std::atan2(b.y() - a.y(), b.x() - a.x())};
}

std::optional<Projection> LaneGraph::project(const Pose& pose, double max_distance, double max_yaw) const
{
    std::optional<Projection> best;
    const Vec2 q(pose.x, pose.y);
    for (size_t i = 0; i < edges.size(); ++i) {
        const auto& e = edges[i];
        for (size_t k = 1; k < e.points.size(); ++k) {
            const Vec2 d = e.points[k] - e.points[k - 1];
            double len2 = d.squaredNorm();
            double u = len2 > 0 ? std::clamp((q - e.points[k - 1]).dot(d) / len2, 0.0, 1.0) : 0.0;
            double dist = (e.points[k - 1] + u * d - q).norm();
            if (dist > max_distance || (best && dist >= best->distance)) continue;
            double yaw_error = std::abs(cpm::vehicle::wrap_angle(pose.yaw - std::atan2(d.y(), d.x())));
            if (yaw_error > max_yaw) continue;
            best = Projection{i, e.s[k - 1] + u * std::sqrt(len2), dist, yaw_error};
        }
    }
    return best;
}

std::vector<size_t> LaneGraph::shortest_path(size_t from_edge, size_t goal_node) const
{
    // Dijkstra over edges: the cost of an edge is its length; done when an edge ends at the goal.
    std::vector<double> cost(edges.size(), std::numeric_limits<double>::infinity());
    std::vector<size_t> previous(edges.size(), SIZE_MAX);
    using Item = std::pair<double, size_t>;
    std::priority_queue<Item, std::vector<Item>, std::greater<>> open;
    cost[from_edge] = 0;
    open.push({0, from_edge});
    while (!open.empty()) {
        auto [c, e] = open.top();
        open.pop();
        if (c > cost[e]) continue;
        if (edges[e].to == goal_node) {
            std::vector<size_t> path;
            for (size_t at = e; at != SIZE_MAX; at = previous[at]) path.push_back(at);
            std::reverse(path.begin(), path.end());
            return path;
        }
        for (size_t n : successors[e]) {
            double nc = c + edges[n].length();
            if (nc < cost[n]) cost[n] = nc, previous[n] = e, open.push({nc, n});
        }
    }
    return {};
}

std::optional<size_t> LaneGraph::node_index(int id) const
{
    for (size_t i = 0; i < nodes.size(); ++i) {
        if (nodes[i].id == id) return i;
    }
    return std::nullopt;
}

double LaneGraph::total_length() const
{
    double total = 0;
    for (const auto& e : edges) total += e.length();
    return total;
}

}  // namespace cpm::routing
