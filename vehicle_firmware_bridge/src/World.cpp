#include <cpm/vehicle/World.hpp>

#include <cpm/Error.hpp>

#include "json_members.hpp"

#include <cpm/checkers/JsonChecker.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdlib>
#include <cmath>
#include <limits>
#include <initializer_list>
#include <optional>

namespace cpm::vehicle {
namespace {

using nlohmann::json;

using Checker = checkers::JsonChecker;

/// A wall [x1, y1, x2, y2] of non-zero length.
std::optional<Segment> read_wall(Checker& c, const json& w, const std::string& at)
{
    if (!w.is_array() || w.size() != 4) {
        c.error(at, "expected [x1, y1, x2, y2], got " + w.dump());
        return std::nullopt;
    }
    double v[4];
    bool ok = true;
    for (size_t k = 0; k < 4; ++k) {
        const auto n = c.number(w[k], Checker::item(at, k));
        ok = ok && n;
        v[k] = n.value_or(0);
    }
    if (!ok) return std::nullopt;
    if (v[0] == v[2] && v[1] == v[3]) {
        c.error(at, "a wall of zero length");
        return std::nullopt;
    }
    return Segment{v[0], v[1], v[2], v[3]};
}

std::vector<Segment> read_walls(Checker& c, const json& walls)
{
    std::vector<Segment> out;
    if (!c.array(walls, "$.walls", "an array of [x1, y1, x2, y2]")) return out;
    for (size_t i = 0; i < walls.size(); ++i) {
        if (auto s = read_wall(c, walls[i], Checker::item("$.walls", i))) out.push_back(*s);
    }
    return out;
}

std::optional<Marker> read_marker(Checker& c, const json& m, const std::string& at)
{
    if (!c.object(m, at, "an object {\"id\", \"x\", \"y\", \"yaw\", \"size\", \"z\"}")) return std::nullopt;
    c.keys(m, at, {"id", "x", "y", "yaw", "size", "z"});
    Marker marker;
    const size_t before = c.errors().size();
    if (!m.contains("id")) c.error(at, "missing \"id\"");
    else if (auto id = c.integer(m["id"], Checker::member(at, "id"))) marker.id = int(*id);
    for (auto [name, field] : {std::pair{"x", &marker.x}, {"y", &marker.y}, {"yaw", &marker.yaw}}) {
        *field = c.number_member(m, at, name).value_or(0);
    }
    if (m.contains("size")) marker.size = c.number(m["size"], Checker::member(at, "size")).value_or(marker.size);
    if (marker.size <= 0) c.error(Checker::member(at, "size"), "must be > 0");
    if (m.contains("z")) marker.z = c.number(m["z"], Checker::member(at, "z")).value_or(marker.z);
    if (marker.size > 0 && marker.z - marker.size / 2 < 0) {
        c.error(Checker::member(at, "z"), "the marker's lower edge is below the floor (z < size / 2)");
    }
    if (c.errors().size() != before) return std::nullopt;
    return marker;
}

std::vector<Marker> read_markers(Checker& c, const json& markers)
{
    std::vector<Marker> out;
    if (!c.array(markers, "$.markers", "an array of {\"id\", \"x\", \"y\", \"yaw\", \"size\"}")) return out;
    for (size_t i = 0; i < markers.size(); ++i) {
        const std::string at = Checker::item("$.markers", i);
        auto marker = read_marker(c, markers[i], at);
        if (!marker) continue;
        const bool twice = std::any_of(out.begin(), out.end(), [&](const Marker& o) { return o.id == marker->id; });
        if (twice) c.error(Checker::member(at, "id"), "id " + std::to_string(marker->id) + " is used twice");
        else out.push_back(*marker);
    }
    return out;
}

std::optional<Gate> read_gate(Checker& c, const json& g, const std::string& at, const std::vector<Marker>& markers)
{
    if (!c.object(g, at, "an object {\"left\": ID, \"right\": ID}")) return std::nullopt;
    c.keys(g, at, {"left", "right"});
    Gate gate;
    bool ok = true;
    for (auto [name, field] : {std::pair{"left", &gate.left}, {"right", &gate.right}}) {
        const std::string p = Checker::member(at, name);
        const auto id = g.contains(name) ? c.integer(g[name], p) : std::nullopt;
        if (!g.contains(name)) c.error(p, "missing (a marker id)");
        if (!id) {
            ok = false;
            continue;
        }
        *field = int(*id);
        if (std::none_of(markers.begin(), markers.end(), [&](const Marker& m) { return m.id == *field; })) {
            c.error(p, "no marker has id " + std::to_string(*field));
            ok = false;
        }
    }
    if (ok && gate.left == gate.right) {
        c.error(at, "left and right are the same marker");
        ok = false;
    }
    return ok ? std::optional<Gate>(gate) : std::nullopt;
}

std::vector<Gate> read_gates(Checker& c, const json& gates, const std::vector<Marker>& markers)
{
    std::vector<Gate> out;
    if (!c.array(gates, "$.gates", "an array of {\"left\": ID, \"right\": ID}")) return out;
    for (size_t i = 0; i < gates.size(); ++i) {
        if (auto g = read_gate(c, gates[i], Checker::item("$.gates", i), markers)) out.push_back(*g);
    }
    return out;
}

/// A side (size) in metres, > 0, if the member is given; `fallback` otherwise.
double side_member(Checker& c, const json& m, const std::string& at, double fallback)
{
    if (!m.contains("size")) return fallback;
    const auto v = c.number(m["size"], Checker::member(at, "size"));
    if (v && *v <= 0) c.error(Checker::member(at, "size"), "must be > 0");
    return v.value_or(fallback);
}

/// `"roof_markers": {"<vehicle id>": {"id": N, "size": 0.08, "z": 0.1}}`: one marker per car, no
/// marker id on two roofs.
std::vector<RoofMarker> read_roof_markers(Checker& c, const json& roofs)
{
    std::vector<RoofMarker> out;
    if (!c.object(roofs, "$.roof_markers", "an object {\"<vehicle id>\": {\"id\", \"size\", \"z\"}}")) return out;
    for (auto it = roofs.begin(); it != roofs.end(); ++it) {
        const std::string at = "$.roof_markers[\"" + it.key() + "\"]";
        RoofMarker r;
        char* end = nullptr;
        const long vehicle = std::strtol(it.key().c_str(), &end, 10);
        if (it.key().empty() || *end != '\0' || vehicle < 1 || vehicle > 255) {
            c.error(at, "the key must be a vehicle id 1..255, got \"" + it.key() + "\"");
            continue;
        }
        r.vehicle_id = int(vehicle);
        if (!c.object(*it, at, "an object {\"id\", \"size\", \"z\"}")) continue;
        c.keys(*it, at, {"id", "size", "z"});
        const size_t before = c.errors().size();
        if (!it->contains("id")) c.error(at, "missing \"id\" (the marker's id)");
        else if (auto id = c.integer((*it)["id"], Checker::member(at, "id"), 0)) r.id = int(*id);
        r.size = side_member(c, *it, at, r.size);
        if (it->contains("z")) r.z = c.number((*it)["z"], Checker::member(at, "z"), 0, 10).value_or(r.z);
        if (c.errors().size() != before) continue;
        for (const auto& o : out) {
            if (o.id == r.id) {
                c.error(Checker::member(at, "id"), "marker " + std::to_string(r.id) + " is on the roofs of cars " +
                                                       std::to_string(o.vehicle_id) + " and " + std::to_string(r.vehicle_id) +
                                                       " (the overhead camera could not tell them apart)");
            }
        }
        out.push_back(r);
    }
    std::sort(out.begin(), out.end(), [](const RoofMarker& a, const RoofMarker& b) { return a.vehicle_id < b.vehicle_id; });
    return out;
}

/// `"floor_markers": [{"id", "x", "y", "yaw", "size"}]`: ids unique and on no roof.
std::vector<FloorMarker> read_floor_markers(Checker& c, const json& floors, const std::vector<RoofMarker>& roofs)
{
    std::vector<FloorMarker> out;
    if (!c.array(floors, "$.floor_markers", "an array of {\"id\", \"x\", \"y\", \"yaw\", \"size\"}")) return out;
    for (size_t i = 0; i < floors.size(); ++i) {
        const std::string at = Checker::item("$.floor_markers", i);
        const json& m = floors[i];
        if (!c.object(m, at, "an object {\"id\", \"x\", \"y\", \"yaw\", \"size\"}")) continue;
        c.keys(m, at, {"id", "x", "y", "yaw", "size"});
        FloorMarker f;
        const size_t before = c.errors().size();
        if (!m.contains("id")) c.error(at, "missing \"id\"");
        else if (auto id = c.integer(m["id"], Checker::member(at, "id"), 0)) f.id = int(*id);
        for (auto [name, field] : {std::pair{"x", &f.x}, {"y", &f.y}, {"yaw", &f.yaw}}) *field = c.number_member(m, at, name).value_or(0);
        f.size = side_member(c, m, at, f.size);
        if (c.errors().size() != before) continue;
        const std::string id_at = Checker::member(at, "id");
        if (std::any_of(out.begin(), out.end(), [&](const FloorMarker& o) { return o.id == f.id; })) {
            c.error(id_at, "id " + std::to_string(f.id) + " is used twice");
            continue;
        }
        for (const auto& r : roofs) {
            if (r.id == f.id) c.error(id_at, "id " + std::to_string(f.id) + " is also the roof marker of car " + std::to_string(r.vehicle_id));
        }
        out.push_back(f);
    }
    return out;
}

}  // namespace

void World::set_overhead_markers(std::vector<RoofMarker> roof, std::vector<FloorMarker> floor)
{
    roof_markers_ = std::move(roof);
    floor_markers_ = std::move(floor);
}

const RoofMarker* World::roof_marker(int marker_id) const
{
    for (const auto& r : roof_markers_) {
        if (r.id == marker_id) return &r;
    }
    return nullptr;
}

const RoofMarker* World::roof_marker_of(int vehicle_id) const
{
    for (const auto& r : roof_markers_) {
        if (r.vehicle_id == vehicle_id) return &r;
    }
    return nullptr;
}

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
    if (!roof_markers_.empty()) {
        j["roof_markers"] = json::object();
        for (const auto& r : roof_markers_) j["roof_markers"][std::to_string(r.vehicle_id)] = {{"id", r.id}, {"size", r.size}, {"z", r.z}};
    }
    if (!floor_markers_.empty()) {
        j["floor_markers"] = json::array();
        for (const auto& f : floor_markers_) {
            j["floor_markers"].push_back({{"id", f.id}, {"x", f.x}, {"y", f.y}, {"yaw", f.yaw}, {"size", f.size}});
        }
    }
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
    Checker c(source);
    const auto j = c.parse(json_text);
    c.throw_if_errors();
    if (!c.object(*j, "$", "an object with \"walls\", \"markers\" and \"gates\"")) c.throw_if_errors();
    c.keys(*j, "$", {"walls", "markers", "gates", "roof_markers", "floor_markers"});
    const json none = json::array();
    std::vector<Segment> walls = read_walls(c, j->value("walls", none));
    std::vector<Marker> markers = read_markers(c, j->value("markers", none));
    std::vector<Gate> gates = read_gates(c, j->value("gates", none), markers);
    std::vector<RoofMarker> roofs = read_roof_markers(c, j->value("roof_markers", json::object()));
    std::vector<FloorMarker> floors = read_floor_markers(c, j->value("floor_markers", none), roofs);
    c.throw_if_errors();
    World world(std::move(walls), std::move(markers), std::move(gates));
    world.set_overhead_markers(std::move(roofs), std::move(floors));
    return world;
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
