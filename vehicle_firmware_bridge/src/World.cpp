#include <cpm/vehicle/World.hpp>

#include <cpm/Error.hpp>

#include "json_members.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <initializer_list>

namespace cpm::vehicle {
namespace {

using nlohmann::json;

[[noreturn]] void fail(const std::string& source, const std::string& where, const std::string& what)
{
    throw Error(source + ": " + where + ": " + what);
}

double number_at(const json& j, const std::string& source, const std::string& where)
{
    if (!j.is_number()) fail(source, where, "expected a number, got " + j.dump());
    double v = j.get<double>();
    if (!std::isfinite(v)) fail(source, where, "expected a finite number");
    return v;
}

/// Fails on a member of `object` that is not one of `known` (listed in the message).
void only_members(const json& object, std::initializer_list<const char*> known, const std::string& source, const std::string& where)
{
    for (auto it = object.begin(); it != object.end(); ++it) {
        bool ok = false;
        for (auto* k : known) ok = ok || it.key() == k;
        if (ok) continue;
        std::string list;
        for (auto* k : known) list += (list.empty() ? "" : ", ") + std::string(k);
        fail(source, where.empty() ? it.key() : where + "." + it.key(), "unknown member (known: " + list + ")");
    }
}

std::vector<Segment> parse_walls(const json& walls, const std::string& source)
{
    if (!walls.is_array()) fail(source, "walls", "expected an array of [x1, y1, x2, y2]");
    std::vector<Segment> out;
    for (size_t i = 0; i < walls.size(); ++i) {
        std::string where = "walls[" + std::to_string(i) + "]";
        const json& w = walls[i];
        if (!w.is_array() || w.size() != 4) fail(source, where, "expected [x1, y1, x2, y2], got " + w.dump());
        Segment s{number_at(w[0], source, where + "[0]"), number_at(w[1], source, where + "[1]"),
                  number_at(w[2], source, where + "[2]"), number_at(w[3], source, where + "[3]")};
        if (s.x1 == s.x2 && s.y1 == s.y2) fail(source, where, "a wall of zero length");
        out.push_back(s);
    }
    return out;
}

std::vector<Marker> parse_markers(const json& markers, const std::string& source)
{
    if (!markers.is_array()) fail(source, "markers", "expected an array of {\"id\", \"x\", \"y\", \"yaw\", \"size\"}");
    std::vector<Marker> out;
    for (size_t i = 0; i < markers.size(); ++i) {
        std::string where = "markers[" + std::to_string(i) + "]";
        const json& m = markers[i];
        if (!m.is_object()) fail(source, where, "expected an object, got " + m.dump());
        only_members(m, {"id", "x", "y", "yaw", "size", "z"}, source, where);
        Marker marker;
        if (!m.contains("id") || !m["id"].is_number_integer()) fail(source, where + ".id", "expected an integer id");
        marker.id = m["id"].get<int>();
        for (auto [name, field] : {std::pair{"x", &marker.x}, {"y", &marker.y}, {"yaw", &marker.yaw}}) {
            if (!m.contains(name)) fail(source, where + "." + name, "missing");
            *field = number_at(m[name], source, where + "." + name);
        }
        if (m.contains("size")) marker.size = number_at(m["size"], source, where + ".size");
        if (marker.size <= 0) fail(source, where + ".size", "must be > 0");
        if (m.contains("z")) marker.z = number_at(m["z"], source, where + ".z");
        if (marker.z - marker.size / 2 < 0) fail(source, where + ".z", "the marker's lower edge is below the floor (z < size / 2)");
        for (const Marker& other : out) {
            if (other.id == marker.id) fail(source, where + ".id", "id " + std::to_string(marker.id) + " is used twice");
        }
        out.push_back(marker);
    }
    return out;
}

std::vector<Gate> parse_gates(const json& gates, const std::vector<Marker>& markers, const std::string& source)
{
    if (!gates.is_array()) fail(source, "gates", "expected an array of {\"left\": ID, \"right\": ID}");
    std::vector<Gate> out;
    for (size_t i = 0; i < gates.size(); ++i) {
        std::string where = "gates[" + std::to_string(i) + "]";
        const json& g = gates[i];
        if (!g.is_object()) fail(source, where, "expected an object, got " + g.dump());
        only_members(g, {"left", "right"}, source, where);
        Gate gate;
        for (auto [name, field] : {std::pair{"left", &gate.left}, {"right", &gate.right}}) {
            if (!g.contains(name) || !g[name].is_number_integer()) fail(source, where + "." + name, "expected a marker id");
            *field = g[name].get<int>();
            bool known = false;
            for (const Marker& m : markers) known = known || m.id == *field;
            if (!known) fail(source, where + "." + name, "no marker has id " + std::to_string(*field));
        }
        if (gate.left == gate.right) fail(source, where, "left and right are the same marker");
        out.push_back(gate);
    }
    return out;
}

}  // namespace

World::World(std::vector<Segment> walls, std::vector<Marker> markers, std::vector<Gate> gates)
    : walls_(std::move(walls)), markers_(std::move(markers)), gates_(std::move(gates))
{
}

std::string World::to_json() const
{
    json j;
    j["walls"] = json::array();
    for (const auto& w : walls_) j["walls"].push_back({w.x1, w.y1, w.x2, w.y2});
    j["markers"] = json::array();
    for (const auto& m : markers_) j["markers"].push_back({{"id", m.id}, {"x", m.x}, {"y", m.y}, {"yaw", m.yaw}, {"size", m.size}, {"z", m.z}});
    j["gates"] = json::array();
    for (const auto& g : gates_) j["gates"].push_back({{"left", g.left}, {"right", g.right}});
    return j.dump(2) + "\n";
}

const Marker* World::marker(int id) const
{
    for (const Marker& m : markers_) {
        if (m.id == id) return &m;
    }
    return nullptr;
}

World World::load(const std::string& path)
{
    return parse(read_text_file(path, "map file"), path);
}

World World::parse(const std::string& json_text, const std::string& source)
{
    json j;
    try {
        j = json::parse(json_text);
    } catch (const json::exception& e) {
        throw Error(source + ": not valid JSON (" + e.what() + ")");
    }
    if (!j.is_object()) fail(source, "$", "expected an object with \"walls\", \"markers\" and \"gates\"");
    only_members(j, {"walls", "markers", "gates"}, source, "");
    std::vector<Segment> walls = j.contains("walls") ? parse_walls(j["walls"], source) : std::vector<Segment>{};
    std::vector<Marker> markers = j.contains("markers") ? parse_markers(j["markers"], source) : std::vector<Marker>{};
    std::vector<Gate> gates = j.contains("gates") ? parse_gates(j["gates"], markers, source) : std::vector<Gate>{};
    return World(std::move(walls), std::move(markers), std::move(gates));
}

double ray_segment_distance(double x, double y, double dx, double dy, const Segment& s)
{
    // Solve (x, y) + t (dx, dy) = p1 + u (p2 - p1) for t >= 0, 0 <= u <= 1.
    double ex = s.x2 - s.x1, ey = s.y2 - s.y1;
    double denom = dx * ey - dy * ex;
    if (std::abs(denom) < 1e-12) return -1;  // parallel
    double wx = s.x1 - x, wy = s.y1 - y;
    double t = (wx * ey - wy * ex) / denom;
    double u = (wx * dy - wy * dx) / denom;
    if (t < 0 || u < 0 || u > 1) return -1;
    return t;
}

double World::cast_ray(double x, double y, double angle, double max_range, const std::vector<Segment>& extra) const
{
    double dx = std::cos(angle), dy = std::sin(angle);
    double best = max_range;
    for (const auto* list : {&walls_, &extra}) {
        for (const auto& s : *list) {
            double d = ray_segment_distance(x, y, dx, dy, s);
            if (d >= 0 && d < best) best = d;
        }
    }
    return best;
}

bool segments_intersect(const Segment& a, const Segment& b)
{
    // Orientation tests (O'Rourke, Computational Geometry in C, 1998, §1.5).
    auto cross = [](double ox, double oy, double px, double py, double qx, double qy) {
        return (px - ox) * (qy - oy) - (py - oy) * (qx - ox);
    };
    auto on_segment = [](double ox, double oy, double px, double py, double qx, double qy) {
        return std::min(ox, px) <= qx && qx <= std::max(ox, px) && std::min(oy, py) <= qy && qy <= std::max(oy, py);
    };
    double d1 = cross(b.x1, b.y1, b.x2, b.y2, a.x1, a.y1), d2 = cross(b.x1, b.y1, b.x2, b.y2, a.x2, a.y2);
    double d3 = cross(a.x1, a.y1, a.x2, a.y2, b.x1, b.y1), d4 = cross(a.x1, a.y1, a.x2, a.y2, b.x2, b.y2);
    if (((d1 > 0 && d2 < 0) || (d1 < 0 && d2 > 0)) && ((d3 > 0 && d4 < 0) || (d3 < 0 && d4 > 0))) return true;
    return (d1 == 0 && on_segment(b.x1, b.y1, b.x2, b.y2, a.x1, a.y1)) ||
           (d2 == 0 && on_segment(b.x1, b.y1, b.x2, b.y2, a.x2, a.y2)) ||
           (d3 == 0 && on_segment(a.x1, a.y1, a.x2, a.y2, b.x1, b.y1)) ||
           (d4 == 0 && on_segment(a.x1, a.y1, a.x2, a.y2, b.x2, b.y2));
}

const Segment* World::wall_hit(const std::vector<Segment>& outline) const
{
    for (const auto& wall : walls_) {
        for (const auto& side : outline) {
            if (segments_intersect(wall, side)) return &wall;
        }
    }
    return nullptr;
}

double point_segment_distance(double x, double y, const Segment& s)
{
    const double dx = s.x2 - s.x1, dy = s.y2 - s.y1;
    const double len2 = dx * dx + dy * dy;
    const double u = len2 > 0 ? std::clamp(((x - s.x1) * dx + (y - s.y1) * dy) / len2, 0.0, 1.0) : 0.0;
    return std::hypot(x - (s.x1 + u * dx), y - (s.y1 + u * dy));
}

double World::nearest_wall(double x, double y) const
{
    double d = std::numeric_limits<double>::infinity();
    for (const auto& w : walls_) d = std::min(d, point_segment_distance(x, y, w));
    return d;
}

}  // namespace cpm::vehicle
