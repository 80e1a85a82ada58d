#include <cpm/lab/Scenario.hpp>

#include <cpm/CommandLine.hpp>
#include <cpm/Error.hpp>
#include <cpm/checkers/YamlChecker.hpp>
#include <cpm/Security.hpp>
#include <cpm/read_text_file.hpp>
#include <cpm/fsm/Loader.hpp>
#include <cpm/fsm/Machine.hpp>
#include <cpm/nodes.hpp>
#include <cpm/timer_ids.hpp>
#include <cpm/vehicle/BridgeNode.hpp>
#include <cpm/vehicle/FirmwareSim.hpp>
#include <cpm/vehicle/World.hpp>
#include <cpm/aruco/Camera.hpp>
#include <cpm/topics.hpp>

#include <nlohmann/json.hpp>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <set>
#include <tuple>
#include <arpa/inet.h>
#include <unistd.h>

namespace cpm::lab {

namespace fs = std::filesystem;

namespace {

/// A process running cpm's program `kind` (a row of cpm/nodes.hpp): what it writes and reads
/// (its security grants), and its timer's id for the lab clock when `timed`.
ProcessPlan process(std::string name, const char* kind, std::vector<std::string> argv, bool restart, int stop_order, int vehicle_id,
                    bool timed = true)
{
    const auto& row = nodes::find(kind);
    return {std::move(name), std::move(argv), restart, stop_order, timed && row.timer ? row.timer(vehicle_id) : "", row.publish, row.subscribe};
}

using Checker = checkers::YamlChecker;

std::vector<std::string> patterns(Checker& c, const YAML::Node& n, const std::string& path)
{
    std::vector<std::string> out;
    if (!n.IsSequence()) {
        c.error(n, path, "expected a list of topic patterns, e.g. [\"*\"]");
        return out;
    }
    for (size_t i = 0; i < n.size(); ++i) {
        if (auto t = c.text(n[i], path + "[" + std::to_string(i) + "]")) out.push_back(*t);
    }
    return out;
}

/// Each car's place at the start in the world: inside its walls, its body clear of them and of
/// every other car's (a typo in start: would otherwise run, and end "ok").
void check_starts(Checker& c, const Scenario& s, const YAML::Node& vehicles)
{
    vehicle::World world;
    try {
        world = vehicle::World::load(s.world);
    } catch (const std::exception& e) {
        c.error(vehicles, "world", e.what());
        return;
    }
    const vehicle::VehicleParameters body;
    std::vector<std::vector<vehicle::Segment>> outlines;
    for (size_t i = 0; i < s.vehicles.size(); ++i) {
        const auto& v = s.vehicles[i];
        const YAML::Node at = vehicles[i]["start"] ? vehicles[i]["start"] : vehicles[i];
        const std::string p = "vehicles[" + std::to_string(i) + "].start";
        char where[96];
        std::snprintf(where, sizeof where, "car %d at (%.3g, %.3g)", v.id, v.x, v.y);
        outlines.push_back(vehicle::FirmwareSim::body_outline(body, {v.x, v.y, v.yaw}));
        if (!world.walls().empty()) {
            // Enclosed: a wall in every direction. A car outside the map sees open space somewhere.
            for (int k = 0; k < 8; ++k) {
                const double angle = k * M_PI / 4;
                if (world.cast_ray(v.x, v.y, angle, 1e6) < 1e6) continue;
                c.error(at, p, std::string(where) + " is outside the world's walls (" + fs::path(s.world).filename().string() +
                                   "): no wall at all toward " + std::to_string(k * 45) + "°");
                break;
            }
        }
        if (const auto* w = world.wall_hit(outlines.back())) {
            char wall[96];
            std::snprintf(wall, sizeof wall, "[%g, %g, %g, %g]", w->x1, w->y1, w->x2, w->y2);
            c.error(at, p, std::string(where) + ": its body crosses the wall " + wall + " at the start");
        }
        for (size_t j = 0; j < i; ++j) {
            bool overlap = false;
            for (const auto& a : outlines[i]) {
                for (const auto& b : outlines[j]) overlap = overlap || vehicle::segments_intersect(a, b);
            }
            // One body wholly inside the other crosses none of its sides: their centres then coincide closely.
            overlap = overlap || std::hypot(v.x - s.vehicles[j].x, v.y - s.vehicles[j].y) < body.width / 2;
            if (overlap) {
                c.error(at, p, std::string(where) + ": its body overlaps car " + std::to_string(s.vehicles[j].id) + "'s (vehicles[" +
                                   std::to_string(j) + "].start) at the start");
            }
        }
    }
}

/// `hosts:`: each computer's address and how to reach it; the one without ssh is the run's own.
void read_hosts(Checker& c, const YAML::Node& root, Scenario& s)
{
    const YAML::Node hosts = root["hosts"];
    if (!hosts) return;
    if (!hosts.IsMap() || hosts.size() == 0) {
        c.error(hosts, "hosts", "expected a map of host name: {address, ssh, cpm}");
        return;
    }
    for (const auto& kv : hosts) {
        HostSpec h;
        h.name = kv.first.as<std::string>("");
        const std::string p = "hosts." + h.name;
        const YAML::Node v = kv.second;
        if (!v.IsMap()) {
            c.error(v, p, "expected a map (address, ssh, cpm)");
            continue;
        }
        c.keys(v, p, {"address", "ssh", "cpm"});
        in_addr parsed{};
        if (!v["address"]) c.error(v, p + ".address", "missing (the IPv4 address its processes use for DDS)");
        else if (auto a = c.text(v["address"], p + ".address")) {
            if (::inet_pton(AF_INET, a->c_str(), &parsed) != 1) c.error(v["address"], p + ".address", "'" + *a + "' is not an IPv4 address");
            else h.address = *a;
        }
        if (v["ssh"]) h.ssh = c.text(v["ssh"], p + ".ssh").value_or("");
        h.cpm = v["cpm"] ? c.text(v["cpm"], p + ".cpm").value_or("") : std::string("/usr");
        if (v["cpm"] && !v["ssh"]) c.error(v["cpm"], p + ".cpm", "only a host reached with ssh has a cpm of its own (the run's own host runs its own programs)");
        s.hosts.push_back(h);
    }
    const auto locals = std::count_if(s.hosts.begin(), s.hosts.end(), [](const HostSpec& h) { return h.ssh.empty(); });
    if (locals != 1) {
        c.error(hosts, "hosts", std::to_string(locals) + " hosts without ssh; exactly one must be the host the run runs on (no ssh: key), every other reached with ssh");
    }
    if (root["ssh_config"]) s.ssh_config = c.file(root["ssh_config"], "ssh_config", s.dir, "ssh config");
    if (root["max_clock_offset"]) s.max_clock_offset_ns = c.duration(root["max_clock_offset"], "max_clock_offset").value_or(s.max_clock_offset_ns);
}

/// A process's `host:`: a name of `hosts:` (with did-you-mean), or "" with an error said.
std::string host_name(Checker& c, const Scenario& s, const YAML::Node& n, const std::string& path)
{
    const auto name = c.text(n, path);
    if (!name) return "";
    std::vector<std::string> known;
    for (const auto& h : s.hosts) known.push_back(h.name);
    if (s.host(*name)) return *name;
    const auto meant = did_you_mean(*name, known);
    std::string list;
    for (const auto& k : known) list += (list.empty() ? "" : ", ") + k;
    c.error(n, path, "no host '" + *name + "'" + (meant ? " (did you mean '" + *meant + "'?)" : std::string()) +
                         (known.empty() ? "; name the lab's computers under hosts:" : "; hosts: " + list));
    return "";
}

/// `discovery:` peers (the default) or server, and `discovery_server:` (a host; default the run's own).
void read_discovery(Checker& c, const YAML::Node& root, Scenario& s)
{
    if (!root["hosts"]) {
        if (root["discovery"] || root["discovery_server"]) {
            const YAML::Node n = root["discovery"] ? root["discovery"] : root["discovery_server"];
            c.error(n, root["discovery"] ? "discovery" : "discovery_server", "only for a lab across hosts: name them under hosts:");
        }
        return;
    }
    if (const YAML::Node d = root["discovery"]) {
        const auto t = c.text(d, "discovery");
        if (t && *t == "server") s.discovery_server = true;
        else if (t && *t != "peers") c.error(d, "discovery", "'" + *t + "': expected peers (unicast to every host's address) or server (fast-discovery-server)");
    }
    if (const YAML::Node d = root["discovery_server"]) {
        if (!s.discovery_server) c.error(d, "discovery_server", "only with discovery: server");
        else s.discovery_server_host = host_name(c, s, d, "discovery_server");
    } else if (s.discovery_server && s.local_host()) {
        s.discovery_server_host = s.local_host()->name;  // the run's own host by default
    }
    if (s.discovery_server && root["security"]) {
        c.error(root["discovery"], "discovery", "server with security: is not supported yet (the server would need a node of its own); use peers");
    }
}

/// `history: {host: …}`.
void read_history(Checker& c, const YAML::Node& root, Scenario& s)
{
    const YAML::Node h = root["history"];
    if (!h) return;
    if (!h.IsMap()) {
        c.error(h, "history", "expected a map (host)");
        return;
    }
    c.keys(h, "history", {"host"});
    if (h["host"]) s.history_host = host_name(c, s, h["host"], "history.host");
}

/// `realtime:` true, false or required.
Realtime read_realtime(Checker& c, const YAML::Node& n, const std::string& path)
{
    try {
        if (n.IsScalar()) return parse_realtime(n.Scalar(), path);  // the words --realtime= takes
    } catch (const Error&) {
    }
    c.error(n, path, "expected true, false or required");
    return Realtime::off;
}

/// The cars: each one's id (once), start, camera, state machine, restart, host and realtime.
void read_vehicles(Checker& c, const YAML::Node& root, const YAML::Node& vehicles, Scenario& s)
{
    if (!vehicles) c.error(root, "vehicles", "missing (a list of cars, each with an id)");
    else if (!vehicles.IsSequence() || vehicles.size() == 0) c.error(vehicles, "vehicles", "expected a list of at least one car");
    else {
        std::map<int, size_t> seen;
        for (size_t i = 0; i < vehicles.size(); ++i) {
            const YAML::Node v = vehicles[i];
            const std::string p = "vehicles[" + std::to_string(i) + "]";
            if (!v.IsMap()) {
                c.error(v, p, "expected a map (id, start, camera, fsm, restart, host, realtime)");
                continue;
            }
            c.keys(v, p, {"id", "start", "camera", "fsm", "restart", "host", "realtime", "firmware"});
            VehicleSpec spec;
            if (!v["id"]) c.error(v, p + ".id", "missing");
            else if (auto id = c.integer(v["id"], p + ".id", 1, 255)) {
                spec.id = int(*id);
                auto [it, fresh] = seen.emplace(spec.id, i);
                if (!fresh) c.error(v["id"], p + ".id", std::to_string(spec.id) + " is given twice (also vehicles[" + std::to_string(it->second) + "])");
            }
            if (v["start"]) {
                const YAML::Node st = v["start"];
                if (!st.IsSequence() || st.size() != 3) c.error(st, p + ".start", "expected [x, y, yaw] in metres and radians");
                else {
                    const auto x = c.number(st[0], p + ".start[0]"), y = c.number(st[1], p + ".start[1]"), yaw = c.number(st[2], p + ".start[2]");
                    if (x && y && yaw) std::tie(spec.x, spec.y, spec.yaw) = std::tuple(*x, *y, *yaw);
                }
            }
            if (v["camera"]) spec.camera = c.file(v["camera"], p + ".camera", s.dir, "camera file");
            if (v["fsm"]) spec.fsm = c.file(v["fsm"], p + ".fsm", s.dir, "state machine");
            if (v["restart"]) spec.restart = c.boolean(v["restart"], p + ".restart").value_or(false);
            if (v["host"]) spec.host = host_name(c, s, v["host"], p + ".host");
            if (v["realtime"]) spec.realtime = read_realtime(c, v["realtime"], p + ".realtime");
            if (const YAML::Node f = v["firmware"]) {
                if (f.IsScalar() && (f.Scalar() == "sim" || f.Scalar() == "avr")) spec.avr = f.Scalar() == "avr";
                else c.error(f, p + ".firmware", "expected sim (firmware_sim) or avr (the car's AVR firmware under firmware_hil)");
            }
            if (v["camera"] && !root["world"]) c.error(v["camera"], p + ".camera", "a camera needs the world's markers: give world");
            if (!spec.fsm.empty() && spec.camera.empty()) {
                // A machine that looks for gates waits for a camera's markers: without one the car
                // never starts (and on the simulated clock the whole lab waits for it).
                const auto machine = fsm::load_file(spec.fsm);
                if (machine.ok() && fsm::uses_markers(*machine.machine))
                    c.error(v["fsm"], p + ".fsm", "its machine works on ArUco markers, but the car has no camera: give it one (camera: FILE)");
            }
            s.vehicles.push_back(spec);
        }
    }

}

/// central_routing: enabled, seed, period, restart, and what it asks of the cars.
void read_routing(Checker& c, const YAML::Node& root, Scenario& s)
{
    if (const YAML::Node r = root["routing"]) {
        if (!r.IsMap()) c.error(r, "routing", "expected a map (enabled, seed, period, restart, host, realtime)");
        else {
            c.keys(r, "routing", {"enabled", "seed", "period", "restart", "host", "realtime"});
            if (r["realtime"]) s.routing.realtime = read_realtime(c, r["realtime"], "routing.realtime");
            if (r["host"]) s.routing.host = host_name(c, s, r["host"], "routing.host");
            if (r["enabled"]) s.routing.enabled = c.boolean(r["enabled"], "routing.enabled").value_or(false);
            if (r["seed"]) s.routing.seed = uint64_t(c.integer(r["seed"], "routing.seed", 0, 1ll << 53).value_or(1));
            if (r["period"]) {
                if (auto d = c.duration(r["period"], "routing.period")) {
                    if (*d % 50'000'000ull) c.error(r["period"], "routing.period", "must be a multiple of 50ms");
                    else s.routing.period_ns = *d;
                }
            }
            if (r["restart"]) s.routing.restart = c.boolean(r["restart"], "routing.restart").value_or(false);
        }
    }
}

/// ips: {camera, world, host, rate, noise, blur}: the overhead camera located in the map, a world
/// with a roof marker on every car of the run.
void read_ips(Checker& c, const YAML::Node& root, Scenario& s)
{
    const YAML::Node n = root["ips"];
    if (!n) return;
    if (!n.IsMap()) {
        c.error(n, "ips", "expected a map (camera, world, host, rate, noise, blur)");
        return;
    }
    c.keys(n, "ips", {"camera", "world", "host", "rate", "noise", "blur"});
    s.ips.enabled = true;
    if (!n["camera"]) c.error(n, "ips.camera", "missing (the overhead camera's file, with its pose in the map)");
    else s.ips.camera = c.file(n["camera"], "ips.camera", s.dir, "camera file");
    if (n["world"]) s.ips.world = c.file(n["world"], "ips.world", s.dir, "world file");
    else if (!s.world.empty()) s.ips.world = s.world;
    else c.error(n, "ips.world", "missing (a map with roof_markers, which marker is on which car, and floor_markers)");
    if (n["host"]) s.ips.host = host_name(c, s, n["host"], "ips.host");
    if (n["rate"]) s.ips.rate_hz = c.number(n["rate"], "ips.rate", 1, 200).value_or(s.ips.rate_hz);
    if (n["noise"]) s.ips.noise = c.number(n["noise"], "ips.noise", 0, 128).value_or(0);
    if (n["blur"]) s.ips.blur = int(c.integer(n["blur"], "ips.blur", 0, 31).value_or(0));
    if (!s.ips.camera.empty()) {
        try {
            aruco::Camera::load(s.ips.camera, aruco::CameraPlacement::overhead);
        } catch (const cpm::Error& e) {
            c.error(n["camera"], "ips.camera", e.what());
        }
    }
    if (s.ips.world.empty()) return;
    const YAML::Node at = n["world"] ? n["world"] : root["world"];
    try {
        const auto world = vehicle::World::load(s.ips.world);
        for (const auto& v : s.vehicles) {
            if (!world.roof_marker_of(v.id)) c.error(at, "ips.world", "car " + std::to_string(v.id) + " has no roof marker in " + s.ips.world + " (roof_markers)");
        }
    } catch (const cpm::Error& e) {
        c.error(at, "ips.world", e.what());
    }
}

/// A controller's `program:` that names one of cpm's programs (hlc_platoon): a bare name, neither a
/// file beside the scenario nor a Python script.
bool is_cpm_program(const std::string& name, const std::string& dir)
{
    std::error_code ec;
    return !name.empty() && name.find('/') == std::string::npos && fs::path(name).extension() != ".py" && !fs::exists(fs::path(dir) / name, ec);
}

/// A controller's program and its name (default: the program's file name); names are unique.
void read_controller_program(Checker& c, const YAML::Node& n, const std::string& p, const Scenario& s, ControllerSpec& spec,
                             std::map<std::string, std::string>& names)
{
    if (!n["program"]) c.error(n, p + ".program", "missing (the controller: a program, or a Python script)");
    else if (auto t = c.text(n["program"], p + ".program"); t && is_cpm_program(*t, s.dir)) spec.program = *t;
    else spec.program = c.file(n["program"], p + ".program", s.dir, "controller program");
    if (n["name"]) {
        if (auto t = c.text(n["name"], p + ".name")) spec.name = *t;
    } else {
        spec.name = fs::path(spec.program).stem().string();
    }
    if (n["name"] || !spec.program.empty()) {
        if (spec.name.empty() || spec.name.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-") != std::string::npos) {
            c.error(n["name"] ? n["name"] : n, p + ".name", "'" + spec.name + "': use letters, digits, - and _ only");
        } else if (auto [at, fresh] = names.emplace(spec.name, p); !fresh) {
            c.error(n, p + ".name", "'" + spec.name + "' is the name of " + at->second + " too (give each a name:)");
        }
    }
    if (spec.program.find('/') != std::string::npos && !spec.python() && ::access(spec.program.c_str(), X_OK) != 0) {
        c.error(n["program"], p + ".program", spec.program + " is not executable (nor a Python script ending in .py)");
    }
}

/// A controller's arguments; a file beside the scenario is given by its full path (the
/// controller runs elsewhere).
void read_controller_args(Checker& c, const YAML::Node& a, const std::string& p, const Scenario& s, ControllerSpec& spec)
{
    if (!a.IsSequence()) c.error(a, p + ".args", "expected a list of texts, e.g. [\"--gap\", \"1.0s\"]");
    for (size_t k = 0; a.IsSequence() && k < a.size(); ++k) {
        const auto t = c.text(a[k], p + ".args[" + std::to_string(k) + "]");
        if (!t) continue;
        std::error_code ec;
        const bool file = !t->empty() && (*t)[0] != '-' && fs::path(*t).is_relative() && fs::exists(fs::path(s.dir) / *t, ec);
        spec.args.push_back(file ? fs::weakly_canonical(fs::path(s.dir) / *t).string() : *t);
    }
}

/// The cars a controller drives: cars of vehicles:, each driven by one controller only.
void read_controller_vehicles(Checker& c, const YAML::Node& n, const std::string& p, const Scenario& s, ControllerSpec& spec,
                              std::map<int, std::string>& driven_by)
{
    const YAML::Node v = n["vehicles"];
    if (!v) c.error(n, p + ".vehicles", "missing (the ids of the cars it drives, e.g. [1, 2])");
    else if (!v.IsSequence() || v.size() == 0) c.error(v, p + ".vehicles", "expected a list of car ids, e.g. [1, 2]");
    for (size_t k = 0; v && v.IsSequence() && k < v.size(); ++k) {
        const std::string vp = p + ".vehicles[" + std::to_string(k) + "]";
        const auto id = c.integer(v[k], vp, 1, 255);
        if (!id) continue;
        if (std::none_of(s.vehicles.begin(), s.vehicles.end(), [&](const VehicleSpec& car) { return car.id == *id; })) {
            c.error(v[k], vp, std::to_string(*id) + " is no car of vehicles:");
        } else if (auto [at, fresh] = driven_by.emplace(int(*id), p); !fresh) {
            c.error(v[k], vp, "car " + std::to_string(*id) + " is driven by " + at->second + " already");
        } else {
            spec.vehicles.push_back(int(*id));
        }
    }
}

/// A controller's period, its own domain and its host.
void read_controller_placing(Checker& c, const YAML::Node& n, const std::string& p, const Scenario& s, ControllerSpec& spec)
{
    if (n["period"]) {
        if (auto d = c.duration(n["period"], p + ".period")) {
            if (*d < 10'000'000ull || *d % 1'000'000ull) c.error(n["period"], p + ".period", "must be whole milliseconds, at least 10ms");
            else spec.period_ns = *d;
        }
    }
    if (n["domain"]) {
        if (auto d = c.integer(n["domain"], p + ".domain", 0, 232)) {
            if (s.domain && *d == *s.domain) c.error(n["domain"], p + ".domain", std::to_string(*d) + " is the lab's own domain: a controller needs one of its own");
            else spec.domain = int(*d);
        }
    }
    if (n["host"]) spec.host = host_name(c, s, n["host"], p + ".host");
    if (const HostSpec* h = s.host(spec.host); h && !h->ssh.empty() && !spec.python() && !is_cpm_program(spec.program, s.dir)) {
        c.error(n["program"], p + ".program", "on another host a controller is one of cpm's programs or a Python script (copied there)");
    }
}

/// `controllers:`, users' high-level controllers: each a program or Python script, its cars and
/// period; a car is driven by one of them only.
void read_controllers(Checker& c, const YAML::Node& root, Scenario& s)
{
    const YAML::Node list = root["controllers"];
    if (!list) return;
    if (!list.IsSequence()) {
        c.error(list, "controllers", "expected a list of controllers (program, vehicles, period, …)");
        return;
    }
    std::map<int, std::string> driven_by;
    std::map<std::string, std::string> names;
    for (size_t i = 0; i < list.size(); ++i) {
        const std::string p = "controllers[" + std::to_string(i) + "]";
        const YAML::Node n = list[i];
        if (!n.IsMap()) {
            c.error(n, p, "expected a map (program, name, args, vehicles, period, domain, host, realtime)");
            continue;
        }
        c.keys(n, p, {"program", "name", "args", "vehicles", "period", "domain", "host", "realtime"});
        ControllerSpec spec;
        if (n["realtime"]) spec.realtime = read_realtime(c, n["realtime"], p + ".realtime");
        read_controller_program(c, n, p, s, spec, names);
        if (const YAML::Node a = n["args"]) read_controller_args(c, a, p, s, spec);
        read_controller_vehicles(c, n, p, s, spec, driven_by);
        read_controller_placing(c, n, p, s, spec);
        s.controllers.push_back(std::move(spec));
    }
    if (root["security"]) c.error(list, "controllers", "controllers in a secured lab are not supported yet (their own domain is not secured)");
}

/// With routing or controllers the cars run in one simulator, spread over the lanes.
void check_cars_on_lanes(Checker& c, const YAML::Node& root, const YAML::Node& vehicles, const Scenario& s)
{
    if (!s.cars_on_lanes()) return;
    const std::string who = s.routing.enabled ? "routing" : "controllers";
    const std::string driver = s.routing.enabled ? "central routing" : "controllers";
    const YAML::Node at = s.routing.enabled ? root["routing"] : root["controllers"];
    if (!root["lanes"]) c.error(at, s.routing.enabled ? "routing.enabled" : "controllers", driver + " need" + (s.routing.enabled ? "s" : "") + " a lane graph: give lanes");
    if (s.routing.enabled && !s.controllers.empty()) c.error(root["controllers"], "controllers", "either central routing or controllers drive the cars, not both");
    for (size_t i = 0; vehicles.IsSequence() && i < vehicles.size(); ++i) {
        const std::string p = "vehicles[" + std::to_string(i) + "]";
        if (!vehicles[i].IsMap()) continue;  // said above
        if (vehicles[i]["fsm"]) c.error(vehicles[i]["fsm"], p + ".fsm", "a car either follows its fsm or " + driver + ", not both");
        if (vehicles[i]["start"]) c.error(vehicles[i]["start"], p + ".start", "with " + who + " the cars are spread over the lanes; leave start out");
        // They run in one `cpm vehicle sim`: one kind of microcontroller for all of them.
        if (i > 0 && i < s.vehicles.size() && s.vehicles[i].avr != s.vehicles[0].avr)
            c.error(vehicles[i], p + ".firmware",
                    std::string("cars on lanes share one simulation: give every car the same firmware (vehicles[0] has ") +
                        (s.vehicles[0].avr ? "avr" : "sim") + ")");
    }
    std::vector<int> ids;
    for (const auto& v : s.vehicles) ids.push_back(v.id);
    std::sort(ids.begin(), ids.end());
    const bool valid = !ids.empty() && ids.front() > 0 && std::adjacent_find(ids.begin(), ids.end()) == ids.end();  // else said above
    if (valid && ids.back() - ids.front() + 1 != int(ids.size())) {
        c.error(vehicles, "vehicles", "with " + who + " the cars run in one simulator and need consecutive ids (e.g. 1, 2, 3)");
    }
}

/// The run's QoS overrides, what it records and its monitor.
void read_run_options(Checker& c, const YAML::Node& root, Scenario& s)
{
    if (const YAML::Node q = root["qos"]) {
        if (!q.IsMap()) c.error(q, "qos", "expected a map of topic: {reliable, transient_local, history_depth}");
        else {
            for (const auto& kv : q) {
                const std::string topic = kv.first.as<std::string>("");
                const std::string p = "qos." + topic;
                if (!kv.second.IsMap()) {
                    c.error(kv.second, p, "expected a map (reliable, transient_local, history_depth)");
                    continue;
                }
                c.keys(kv.second, p, {"reliable", "transient_local", "history_depth"});
                QosOverride o;
                if (kv.second["reliable"]) o.reliable = c.boolean(kv.second["reliable"], p + ".reliable");
                if (kv.second["transient_local"]) o.transient_local = c.boolean(kv.second["transient_local"], p + ".transient_local");
                if (kv.second["history_depth"]) {
                    if (auto d = c.integer(kv.second["history_depth"], p + ".history_depth", 1, 100000)) o.history_depth = int(*d);
                }
                s.qos[topic] = o;
            }
        }
    }
    if (const YAML::Node t = root["timeouts"]) {
        if (!t.IsMap()) c.error(t, "timeouts", "expected a map (start, step)");
        else {
            c.keys(t, "timeouts", {"start", "step"});
            for (auto [key, into] : {std::pair{"start", &s.timeouts.start_ns}, std::pair{"step", &s.timeouts.step_ns}}) {
                if (!t[key]) continue;
                const std::string path = std::string("timeouts.") + key;
                const auto d = c.duration(t[key], path);
                if (d && *d < 1'000'000) c.error(t[key], path, "must be at least 1ms");
                else if (d) *into = *d;
            }
        }
    }
    if (const YAML::Node r = root["record"]) {
        if (!r.IsMap()) c.error(r, "record", "expected a map (topics, exclude)");
        else {
            c.keys(r, "record", {"topics", "exclude"});
            if (r["topics"]) s.record.topics = patterns(c, r["topics"], "record.topics");
            if (r["exclude"]) s.record.exclude = patterns(c, r["exclude"], "record.exclude");
        }
    }
    if (const YAML::Node m = root["monitor"]) {
        if (m.IsMap()) {
            c.keys(m, "monitor", {"port", "allow_stop", "host"});
            if (!m["port"]) c.error(m, "monitor", "port is missing");
            else if (auto port = c.integer(m["port"], "monitor.port", 1, 65535)) s.monitor_port = int(*port);
            if (m["allow_stop"]) s.monitor_allow_stop = c.boolean(m["allow_stop"], "monitor.allow_stop").value_or(false);
            if (m["host"]) s.monitor_host = host_name(c, s, m["host"], "monitor.host");
        } else if (m.IsScalar() && (m.Scalar() == "off" || m.Scalar() == "false" || m.Scalar() == "none")) {
            s.monitor_port.reset();  // as --monitor off
        } else if (auto port = c.integer(m, "monitor", 1, 65535)) {
            s.monitor_port = int(*port);
        }
    }
}
}  // namespace

Scenario load_scenario(const std::string& path)
{
    Scenario s;
    s.file = path;
    s.dir = fs::path(path).parent_path().string();
    if (s.dir.empty()) s.dir = ".";
    YAML::Node root;
    try {
        root = YAML::Load(read_text_file(path, "scenario file"));
    } catch (const cpm::Error& e) {
        throw ScenarioError(std::vector<Diagnostic>{{"", e.what()}});
    } catch (const YAML::Exception& e) {
        throw ScenarioError(std::vector<Diagnostic>{{path + ":" + std::to_string(e.mark.line + 1), "not YAML: " + e.msg}});
    }
    Checker c(path);
    if (!root.IsMap()) throw ScenarioError(std::vector<Diagnostic>{{path, "expected a map of keys (name, time, duration, world, vehicles, ...)"}});
    c.keys(root, "", {"name", "domain", "time", "duration", "world", "lanes", "vehicles", "routing", "qos", "record", "monitor",
                    "parameters", "security", "hosts", "ssh_config", "max_clock_offset", "discovery", "discovery_server", "history",
                    "controllers", "ips", "timeouts"});
    read_hosts(c, root, s);  // before anything names a host
    read_discovery(c, root, s);

    if (!root["name"]) c.error(root, "name", "missing (the run's name; its folder is runs/<name>-<UTC time>)");
    else if (auto n = c.text(root["name"], "name")) {
        if (n->empty() || n->find_first_of("/\\ ") != std::string::npos) c.error(root["name"], "name", "'" + *n + "': use letters, digits, - and _ only");
        else s.name = *n;
    }
    if (root["domain"]) {
        if (auto d = c.integer(root["domain"], "domain", 0, 232)) s.domain = int(*d);
    }
    if (root["time"]) {
        const auto t = c.text(root["time"], "time");
        if (t && *t == "simulated") s.time = TimeMode::simulated;
        else if (t && *t != "real") c.error(root["time"], "time", "'" + *t + "': expected real or simulated");
    }
    if (!root["duration"]) c.error(root, "duration", "missing (how long the run lasts, e.g. 30s)");
    else if (auto d = c.duration(root["duration"], "duration")) s.duration_ns = *d;
    if (root["world"]) s.world = c.file(root["world"], "world", s.dir, "world file");
    if (root["lanes"]) s.lanes = c.file(root["lanes"], "lanes", s.dir, "lane graph");
    if (root["parameters"]) s.parameters = c.file(root["parameters"], "parameters", s.dir, "parameter file");
    if (root["security"]) {
        if (auto t = c.text(root["security"], "security")) {
            const fs::path p = fs::path(*t).is_absolute() ? fs::path(*t) : fs::path(s.dir) / *t;
            std::error_code ec;
            bool lab = true;
            for (const char* f : {"identity_ca.cert.pem", "identity_ca.key.pem", "permissions_ca.cert.pem", "permissions_ca.key.pem", "governance.p7s"})
                lab = lab && fs::is_regular_file(p / f, ec);
            if (!lab) {
                c.error(root["security"], "security", "'" + *t + "' (" + p.lexically_normal().string() +
                                                          ") is not a lab's security folder with its CAs' keys (make one with: cpm security init DIR)");
            } else {
                s.security = fs::weakly_canonical(p).string();
            }
        }
    }

    const YAML::Node vehicles = root["vehicles"];
    read_vehicles(c, root, vehicles, s);
    read_routing(c, root, s);
    read_controllers(c, root, s);
    read_ips(c, root, s);
    check_cars_on_lanes(c, root, vehicles, s);
    if (!s.cars_on_lanes() && !root["world"]) c.error(root, "world", "missing (the map the cars drive in)");

    read_run_options(c, root, s);
    read_history(c, root, s);
    if (c.ok() && !s.world.empty() && !s.cars_on_lanes()) check_starts(c, s, vehicles);
    if (!c.ok()) throw ScenarioError(c.errors());
    return s;
}

bool ControllerSpec::python() const { return fs::path(program).extension() == ".py"; }

std::map<std::string, int> controller_domains(const Scenario& s, const RunSettings& settings, const std::function<bool(int)>& unavailable)
{
    std::set<int> taken{settings.domain};
    for (const auto& c : s.controllers) {
        if (c.domain) taken.insert(*c.domain);
    }
    std::map<std::string, int> out;
    int next = settings.domain;
    for (const auto& c : s.controllers) {
        if (c.domain) {
            out[c.name] = *c.domain;
        } else if (const auto chosen = settings.controller_domains.find(c.name); chosen != settings.controller_domains.end()) {
            out[c.name] = chosen->second;
        } else {
            for (int tries = 0; tries < 233; ++tries) {
                next = (next + 1) % 233;
                if (!taken.count(next) && !(unavailable && unavailable(next))) break;
            }
            taken.insert(next);
            out[c.name] = next;
        }
    }
    return out;
}

std::string Scenario::discovery_server_locator() const
{
    const HostSpec* h = host(discovery_server_host);
    return h ? h->address + ":" + std::to_string(kDiscoveryServerPort) : "";
}

const HostSpec* Scenario::local_host() const
{
    for (const auto& h : hosts) {
        if (h.ssh.empty()) return &h;
    }
    return nullptr;
}

const HostSpec* Scenario::host(const std::string& host_name) const
{
    if (host_name.empty()) return local_host();
    for (const auto& h : hosts) {
        if (h.name == host_name) return &h;
    }
    return nullptr;
}

std::string security_node_name(const RunSettings& settings, const std::string& process)
{
    std::string name = fs::path(settings.run_dir).filename().string() + "-" + process;
    for (char& ch : name)
        if (!std::isalnum(static_cast<unsigned char>(ch)) && ch != '_' && ch != '-') ch = '-';
    return name;
}

ProcessPlan lab_run_process()
{
    return process("cpm_lab_run", "lab_run", {}, false, 0, 0);
}

std::string remote_run_dir(const RunSettings& settings) { return "/tmp/cpm-runs/" + fs::path(settings.run_dir).filename().string(); }

namespace {

/// The files a JSON file names as {"file": "<path relative to it>"} (a state machine's nested
/// machines, FSMState `file:`), theirs, and so on: each once, absolute. None when it is not JSON.
std::vector<fs::path> included_files(const fs::path& file)
{
    std::vector<fs::path> out;
    std::vector<fs::path> todo{file};
    std::set<fs::path> seen{fs::weakly_canonical(file)};
    while (!todo.empty()) {
        const fs::path f = todo.back();
        todo.pop_back();
        std::vector<const nlohmann::json*> walk;
        nlohmann::json doc;
        try {
            doc = nlohmann::json::parse(read_text_file(f.string(), "file"));
        } catch (const std::exception&) {
            continue;  // not JSON (a camera's YAML), or not readable: copied as it is, the program says what is wrong
        }
        walk.push_back(&doc);
        while (!walk.empty()) {
            const nlohmann::json& j = *walk.back();
            walk.pop_back();
            if (j.is_object() && j.contains("file") && j["file"].is_string()) {
                std::error_code ec;
                const fs::path inc = fs::weakly_canonical(f.parent_path() / j["file"].get<std::string>(), ec);
                if (!ec && fs::is_regular_file(inc, ec) && seen.insert(inc).second) {
                    out.push_back(inc);
                    todo.push_back(inc);
                }
            }
            if (j.is_structured()) {
                for (const auto& v : j) walk.push_back(&v);
            }
        }
    }
    return out;
}

/// A planned process on its host (a scenario with hosts): the host's address for DDS, the other
/// hosts' as peers; on another host, the program as installed there, the files it reads copied
/// into the run's folder there, and what it makes in the run's folder made there.
void place_on_host(ProcessPlan& p, const Scenario& s, const RunSettings& r, std::map<std::string, std::string>& copied_as)
{
    if (s.hosts.empty()) return;
    const HostSpec* here = s.host(p.host);
    if (!here) return;  // named in the scenario's errors
    p.host = here->name;
    // A user's controller is on a domain of its own with its middleware, this host only: no DDS
    // flags; on another host its files go there as cpm's programs' do.
    const bool controller = p.name.rfind("controller_", 0) == 0;
    const bool cpms = p.argv[0].rfind(r.bin_dir + "/", 0) == 0;
    if (!cpms && !controller) return;  // not cpm's (fast-discovery-server): as it is, there too
    if (!here->ssh.empty()) {
        const std::string there = remote_run_dir(r);
        if (cpms) p.argv[0] = here->cpm + "/bin/" + fs::path(p.argv[0]).filename().string();
        const std::string run_dir = r.run_dir + "/";
        for (size_t i = 1; i < p.argv.size(); ++i) {
            std::string& a = p.argv[i];
            std::error_code ec;
            if (a.rfind("/usr/bin/", 0) == 0) continue;  // a system program (python3), there too
            if (a.rfind(run_dir, 0) == 0) {
                a = there + "/" + a.substr(run_dir.size());
            } else if (a.size() > 1 && a[0] == '/' && fs::is_regular_file(a, ec)) {
                const auto included = included_files(a);
                // One name there per file here (maps/gates.json and fsm/gates.json are two
                // files); a file that includes others in a folder of its own, with them as they
                // lie beside it (their common folder's layout), so that its relative names hold.
                auto [it, fresh] = copied_as.emplace(a, fs::path(a).filename().string());
                fs::path root = fs::weakly_canonical(a).parent_path();
                for (const auto& f : included) {
                    while (!root.empty() && root != root.root_path() && fs::relative(f, root).string().rfind("..", 0) == 0) root = root.parent_path();
                }
                if (fresh && !included.empty()) {
                    it->second = "tree_" + std::to_string(copied_as.size()) + "/" + fs::relative(fs::weakly_canonical(a), root).string();
                } else if (fresh) {
                    for (const auto& [other, name] : copied_as) {
                        if (other != a && name == it->second) it->second = std::to_string(copied_as.size()) + "_" + it->second;
                    }
                }
                const std::string copy = there + "/" + it->second;
                p.copies.emplace_back(a, copy);
                const std::string tree = copy.substr(0, copy.size() - fs::relative(fs::weakly_canonical(a), root).string().size());
                for (const auto& f : included) p.copies.emplace_back(f.string(), tree + fs::relative(f, root).string());
                a = copy;
            }
        }
    }
    if (controller) return;
    p.argv.insert(p.argv.end(), {"--dds_interface", here->address});
    if (s.discovery_server) {
        p.argv.insert(p.argv.end(), {"--dds_discovery_server", s.discovery_server_locator()});
        return;
    }
    for (const auto& other : s.hosts) {
        if (other.name != here->name) p.argv.insert(p.argv.end(), {"--dds_initial_peer", other.address});
    }
}

/// A run's plan, built in parts: the services, the cars, what drives them.
class PlanBuilder
{
public:
    PlanBuilder(const Scenario& s, const RunSettings& r) : s_(s), r_(r), domain_(std::to_string(r.domain)) {}

    /// The history (recording every sample of the run), the parameter server and the monitor.
    void services()
    {
        std::vector<std::string> history{program("cpm_history"), "--window", "60s", "--record", (fs::path(r_.run_dir) / "recording.db").string(),
                                         "--record-name", s_.name, "--save-dir", r_.run_dir, "--dds_domain", domain_};
        for (const auto& t : s_.record.topics) {
            if (t != "*") history.insert(history.end(), {"--include", cpm::cli::glob_regex(t)});
        }
        for (const auto& t : s_.record.exclude) history.insert(history.end(), {"--exclude", cpm::cli::glob_regex(t)});
        if (s_.discovery_server) {
            // Started first, stopped last: every participant of the run finds the others through it.
            ProcessPlan server{.name = "discovery_server",
                               .argv = {"/usr/bin/fast-discovery-server", "-i", "0", "-l", s_.host(s_.discovery_server_host)->address, "-p",
                                        std::to_string(Scenario::kDiscoveryServerPort)},
                               .stop_order = 10,
                               .host = s_.discovery_server_host};
            plan_.push_back(server);
        }
        // On the simulated clock the recorder is one of the clock's nodes: a clock that outran it
        // (a busy machine) would lose samples to the recording, which then differs run to run.
        if (simulated()) history.push_back("--simulated-clock");
        add("cpm_history", "cpm_history", history, false, 9, 0, s_.history_host);
        if (simulated()) plan_.back().timer = timer_ids::history;
        if (!s_.parameters.empty()) {
            add("parameters", "parameter_server", {program("cpm"), "param", "serve", s_.parameters, "--dds_domain", domain_}, false, 8, 0, "");
        }
        if (!s_.monitor_port) return;
        std::vector<std::string> argv{program("cpm"), "monitor", "--port", std::to_string(*s_.monitor_port)};
        if (!s_.world.empty()) argv.insert(argv.end(), {"--world", s_.world});
        if (!s_.lanes.empty()) argv.insert(argv.end(), {"--lanes", s_.lanes});
        if (s_.monitor_allow_stop) argv.push_back("--allow-stop");
        argv.insert(argv.end(), {"--dds_domain", domain_});
        add("monitor", "monitor", argv, false, 8, 0, s_.monitor_host);
        if (!s_.monitor_allow_stop) plan_.back().publish.clear();  // it writes stop requests only with --allow-stop
    }

    /// The cars: with routing all in one simulator spread over the lanes; else each car's
    /// simulator, bridge and camera supervised by the run itself, so that one that dies is
    /// restarted alone (restart: true), the bridge finding its simulator's new pty by the link in
    /// the run's folder; stopped bridge first, so that it never reports a lost link.
    void cars()
    {
        if (s_.cars_on_lanes()) {
            int first = 255;
            bool restart = false;
            Realtime realtime = Realtime::off;  // one simulator and bridge for all: the strictest car's
            for (const auto& v : s_.vehicles) first = std::min(first, v.id), restart = restart || v.restart, realtime = std::max(realtime, v.realtime);
            add("cars", "vehicle_sim",
                common({program("cpm"), "vehicle", "sim", "--id", std::to_string(first), "--count", std::to_string(s_.vehicles.size()), "--lanes",
                        s_.lanes, "--seed", std::to_string(s_.routing.seed), "--firmware", s_.vehicles.front().avr ? "avr" : "sim"},
                       realtime),
                restart, 5, first, s_.vehicles.front().host);
            truth_only(plan_.back(), true);
            plan_.back().timer = timer_ids::firmware_sim(first) + "," + timer_ids::vehicle_bridge(first);
            return;
        }
        for (const auto& v : s_.vehicles) {
            const std::string id = std::to_string(v.id);
            const std::string start = number(v.x) + "," + number(v.y) + "," + number(v.yaw);
            const std::string link = (fs::path(r_.run_dir) / ("car_" + id + ".tty")).string();
            const char* microcontroller = v.avr ? "firmware_hil" : "firmware_sim";
            add("sim_" + id, microcontroller,
                common({program(microcontroller), "--vehicle_id", id, "--map", s_.world, "--start", start, "--link", link}, v.realtime),
                v.restart, 6, v.id, v.host);
            truth_only(plan_.back(), false);
            add("bridge_" + id, "vehicle_bridge", common({program("vehicle_bridge"), "--vehicle_id", id, "--device", link, "--start", start}, v.realtime),
                v.restart, 5, v.id, v.host);
            // In real time the camera starts at once; on the simulated clock it ticks with the car.
            if (!v.camera.empty()) {
                add("camera_" + id, "camera_sim",
                    common({program("camera_sim"), "--vehicle_id", id, "--camera", v.camera, "--map", s_.world, "--rate", "30"}, v.realtime), v.restart, 4,
                    v.id, v.host, simulated());
                truth_only(plan_.back(), false);
                erase(plan_.back().publish, topics::ips_camera_frame.name);
            }
        }
    }

    /// The lab's positioning system: the overhead camera (simulated) and ips_node, on the clock
    /// with the cars.
    void positioning()
    {
        if (!s_.ips.enabled) return;
        const std::string rate = number(s_.ips.rate_hz);
        add("ips_camera", "camera_sim",
            common({program("camera_sim"), "--overhead", "--camera", s_.ips.camera, "--map", s_.ips.world, "--rate", rate, "--noise",
                    number(s_.ips.noise), "--blur", std::to_string(s_.ips.blur)}),
            false, 4, 0, s_.ips.host, simulated());
        if (simulated()) plan_.back().timer = timer_ids::ips_camera;
        truth_only(plan_.back(), false);
        erase(plan_.back().publish, topics::camera_frame.name);
        std::vector<std::string> ips{program("ips_node"), "--camera", s_.ips.camera, "--world", s_.ips.world};
        if (simulated()) ips.insert(ips.end(), {"--rate", rate});
        add("ips", "ips_node", common(ips), false, 3, 0, s_.ips.host, simulated());
    }

    /// What drives the cars: each camera's marker finder, central routing, the state machines.
    void drivers()
    {
        for (const auto& v : s_.vehicles) {
            if (v.camera.empty()) continue;
            const std::string id = std::to_string(v.id);
            add("aruco_" + id, "aruco_node", common({program("aruco_node"), "--vehicle_id", id, "--camera", v.camera, "--world", s_.world}, v.realtime),
                v.restart, 3, v.id, v.host, simulated());
        }
        if (s_.routing.enabled) {
            std::string ids;
            for (const auto& v : s_.vehicles) ids += (ids.empty() ? "" : ",") + std::to_string(v.id);
            add("central_routing", "central_routing",
                common({program("central_routing"), "--vehicle_ids", ids, "--lanes", s_.lanes, "--seed", std::to_string(s_.routing.seed), "--period",
                        std::to_string(s_.routing.period_ns / 1'000'000) + "ms"},
                       s_.routing.realtime),
                s_.routing.restart, 1, 0, s_.routing.host);
        }
        controllers();
        for (const auto& v : s_.vehicles) {
            if (v.fsm.empty()) continue;
            const std::string id = std::to_string(v.id);
            std::vector<std::string> fsm{program("fsm_node"), "--vehicle_id", id, "--fsm", v.fsm, "--report"};
            // On the simulated clock the machine looks at the sensors' rate, with the car's own
            // tick: it ticks once per range sample anyway, and each of its ticks at 80 Hz was a
            // step of the lab's clock of its own (17 steps per 100 ms instead of 10). A sample
            // reaches the bridge's command at the same tick as before (the next one).
            if (simulated()) fsm.insert(fsm.end(), {"--rate", number(1e9 / double(cpm::vehicle::kSimulatedStatePeriod_ns))});
            add("fsm_" + id, "fsm_node", common(fsm, v.realtime), v.restart, 1, v.id, v.host);
        }
    }

    /// Each controller on its own domain with its middleware, which the lab clock waits for. The
    /// controller is given its cars, its domain and the lab's clock after its own arguments.
    void controllers()
    {
        const auto domains = controller_domains(s_, r_);
        for (const auto& c : s_.controllers) {
            const int domain = domains.at(c.name);
            std::string ids;
            for (int v : c.vehicles) ids += (ids.empty() ? "" : ",") + std::to_string(v);
            add("hlc_" + c.name, "hlc_middleware",
                common({program("hlc_middleware"), "--vehicle_ids", ids, "--controller_domain", std::to_string(domain), "--name", c.name,
                        "--period", std::to_string(c.period_ns / 1'000'000) + "ms"},
                       c.realtime),
                false, 2, c.vehicles.front(), c.host, false);
            plan_.back().timer = timer_ids::hlc_middleware(c.name);
            std::vector<std::string> argv;
            // Python finds cpm beside the run's programs: the build tree's, or the installed one
            // (on another host, beside cpm's programs there).
            if (c.python()) {
                const HostSpec* h = s_.host(c.host);
                const fs::path prefix = h && !h->ssh.empty() ? fs::path(h->cpm) : fs::path(r_.bin_dir).parent_path();
                argv = {"/usr/bin/env", "PYTHONPATH=" + (prefix / "python").string() + ":" + (prefix / "lib/python3/dist-packages").string(),
                        "/usr/bin/python3", c.program};
            }
            else argv = {c.program.find('/') == std::string::npos ? program(c.program) : c.program};
            argv.insert(argv.end(), c.args.begin(), c.args.end());
            argv.insert(argv.end(), {"--vehicle_ids", ids, "--dds_domain", std::to_string(domain)});
            if (simulated()) argv.push_back("--simulated_time");
            if (c.realtime != Realtime::off) argv.push_back(realtime_flag(c.realtime));
            add("controller_" + c.name, "hlc_controller", argv, false, 1, c.vehicles.front(), c.host, false);
        }
    }

    /// Each process on its host; in a secured run each as a node of its own, allowed what it uses
    /// (issued by the run). Throws ScenarioError naming every program that is missing.
    std::vector<ProcessPlan> finish()
    {
        std::map<std::string, std::string> copied_as;
        for (auto& p : plan_) place_on_host(p, s_, r_, copied_as);
        if (!s_.security.empty()) {
            for (auto& p : plan_) {
                const std::string node = security_node_name(r_, p.name);
                p.security_node = (fs::path(s_.security) / "nodes" / node).string();
                std::string given = p.security_node;
                if (const HostSpec* h = s_.host(p.host); h && !h->ssh.empty()) {
                    // Another host gets its own nodes' files, copied into the run's folder there;
                    // never a CA's key (the lab's folder stays here).
                    given = remote_run_dir(r_) + "/security/" + node;
                    for (const char* f : security::kNodeFileNames) p.copies.emplace_back(p.security_node + "/" + f, given + "/" + f);
                }
                p.argv.insert(p.argv.end(), {"--security", given});
            }
        }
        if (!missing_.empty()) {
            std::vector<Diagnostic> errors;
            for (const auto& m : missing_) errors.push_back({s_.file, "the run needs " + m + ", which does not exist (build it: ./lab build)"});
            throw ScenarioError(errors);
        }
        return std::move(plan_);
    }

private:
    bool simulated() const { return r_.time == TimeMode::simulated; }
    static void erase(std::vector<std::string>& topics, const std::string& topic)
    {
        topics.erase(std::remove(topics.begin(), topics.end(), topic), topics.end());
    }
    /// A simulator or camera of the run writes and reads the cars' true poses on one topic:
    /// vehicleObservationTruth beside a positioning system (given --truth_topic), else
    /// vehicleObservation; it is allowed that one only (and the lab's vehicleObservation for a
    /// bridge in the same process, `bridge`).
    void truth_only(ProcessPlan& p, bool bridge) const
    {
        const std::string other = s_.ips.enabled ? topics::vehicle_observation.name : topics::vehicle_observation_truth.name;
        erase(p.publish, other);
        if (!(bridge && other == topics::vehicle_observation.name)) erase(p.subscribe, other);
        if (!s_.ips.enabled) return;
        // --truth_topic before the common flags, as the program's own.
        const auto at = std::find(p.argv.begin(), p.argv.end(), "--dds_domain");
        p.argv.insert(at, {"--truth_topic", topics::vehicle_observation_truth.name});
    }
    std::string program(const std::string& name)
    {
        const std::string p = (fs::path(r_.bin_dir) / name).string();
        if (::access(p.c_str(), X_OK) != 0 && std::find(missing_.begin(), missing_.end(), p) == missing_.end()) missing_.push_back(p);
        return p;
    }
    /// The flags every node of the run takes: its domain, the simulated clock, and --realtime
    /// where the scenario marks it.
    std::vector<std::string> common(std::vector<std::string> argv, Realtime realtime = Realtime::off) const
    {
        argv.insert(argv.end(), {"--dds_domain", domain_});
        if (simulated()) argv.push_back("--simulated_time");
        if (realtime != Realtime::off) argv.push_back(realtime_flag(realtime));
        return argv;
    }
    static std::string realtime_flag(Realtime realtime) { return realtime == Realtime::required ? "--realtime=required" : "--realtime"; }
    static std::string number(double v)
    {
        char b[32];
        std::snprintf(b, sizeof b, "%.6g", v);
        return b;
    }
    void add(std::string name, const char* kind, std::vector<std::string> argv, bool restart, int stop_order, int vehicle_id,
             const std::string& host, bool timed = true)
    {
        plan_.push_back(process(std::move(name), kind, std::move(argv), restart, stop_order, vehicle_id, timed));
        plan_.back().host = host;
        plan_.back().vehicle_id = vehicle_id;
    }

    const Scenario& s_;
    const RunSettings& r_;
    const std::string domain_;
    std::vector<std::string> missing_;
    std::vector<ProcessPlan> plan_;
};

}  // namespace

std::vector<ProcessPlan> plan_run(const Scenario& s, const RunSettings& r)
{
    PlanBuilder plan(s, r);
    plan.services();
    plan.cars();
    plan.positioning();
    plan.drivers();
    return plan.finish();
}

}  // namespace cpm::lab
