// cpm vehicle sim: one simulated car (firmware_sim + vehicle_bridge joined by a pty) or several.
#include "Command.hpp"

#include <cpm/ChildProcess.hpp>
#include <cpm/ProcessGroup.hpp>
#include <cpm/CommandLine.hpp>
#include <cpm/Error.hpp>
#include <cpm/aruco/Camera.hpp>
#include <cpm/routing/Simulate.hpp>
#include <cpm/timer_ids.hpp>
#include <cpm/vehicle/BridgeNode.hpp>
#include <cpm/vehicle/FirmwareSimNode.hpp>
#include <cpm/vehicle/VehicleModel.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <string>
#include <thread>
#include <vector>

namespace {

const char* const kVehicleSimHelp =
    "usage: cpm vehicle sim --id N [--count K] [--map FILE] [--start X,Y,YAW] [--spacing M]\n"
    "                       [--lanes FILE [--seed S]] [--process-per-car] [--firmware sim|avr]\n"
    "                       [--params FILE] [--calibration FILE] [--camera FILE [--camera-rate HZ]]\n"
    "                       [--truth_topic T] [--dds_domain N]\n"
    "\n"
    "Starts simulated car N: firmware_sim (vehicle model, sensors, watchdog) and vehicle_bridge,\n"
    "joined by a pseudo-terminal exactly as a real car's computer and microcontroller are by a\n"
    "serial line. The car publishes vehicleState, rangeSensors and vehicleObservation and obeys\n"
    "vehicleCommand* for its id. With --count K, cars N .. N+K-1 share one world, each --spacing\n"
    "metres (default 0.6) behind the previous one along the start heading; their rangers see\n"
    "each other. With --lanes FILE (a lane graph) the cars are spread over its lanes instead, as\n"
    "`cpm routing simulate` spreads them (outside conflict zones, bodies at least 0.38 m apart,\n"
    "chosen by --seed, default 1), ready for central_routing. With --camera FILE (a camera file;\n"
    "needs --map), each car also gets a synthetic camera (camera_sim) publishing cameraFrame at\n"
    "--camera-rate Hz (default 30) from its true pose; run aruco_node to turn the frames into\n"
    "arucoMarkers. All cars run in one firmware_sim and one vehicle_bridge process (each car still\n"
    "behind its own pty, line and loop); --process-per-car starts a pair of processes per car\n"
    "instead (more isolation, fewer cars per machine). --firmware avr runs each car's real\n"
    "firmware (the ATmega2560 ELF a car is flashed with) in firmware_hil instead of firmware_sim,\n"
    "one chip per car; the bridge is the same. With --simulated_time the cars and their\n"
    "cameras follow the lab's simulated clock (give aruco_node --simulated_time and the camera's\n"
    "rate as --rate too): it prints the timers to name to `cpm lab clock --simulated --nodes`, and\n"
    "ends when that clock stops them. Runs until Ctrl-C, then prints each car's statistics (JSON\n"
    "lines). --truth_topic vehicleObservationTruth: the cars' true poses go there instead of to\n"
    "vehicleObservation, for a lab whose positioning system (ips_node) writes vehicleObservation.\n";

std::string pose_text(double x, double y, double yaw)
{
    char text[96];
    std::snprintf(text, sizeof text, "%.6f,%.6f,%.6f", x, y, yaw);
    return text;
}

/// What `cpm vehicle sim` was told, checked before anything starts.
struct SimRequest
{
    cpm::cli::ParsedArgs parsed;
    long long first = 1, count = 1;
    bool avr = false;        ///< --firmware avr: the real firmware under firmware_hil
    bool per_car = false;    ///< a simulator and a bridge process per car
    bool simulated = false;  ///< --simulated_time
    std::string camera_rate;
    std::vector<std::string> poses;  ///< each car's start, "x,y,yaw"
};

std::string joined(const std::vector<std::string>& items, const char* separator)
{
    std::string text;
    for (const auto& item : items) text += (text.empty() ? "" : separator) + item;
    return text;
}

/// Start poses: a row behind --start, --spacing apart, or spread over a lane graph as
/// central_routing's simulation spreads them (outside conflict zones, by the seed).
std::vector<std::string> start_poses(const cpm::cli::ParsedArgs& parsed, long long count)
{
    const double spacing = cpm::cli::parse_number("--spacing", parsed.get("--spacing", "0.6"), 0, 100);
    const auto start = cpm::vehicle::parse_pose("--start", parsed.get("--start", "0,0,0"));
    std::vector<std::string> poses;
    if (parsed.has("--lanes")) {
        if (parsed.has("--start")) throw cpm::cli::UsageError("cpm vehicle sim: give --start or --lanes, not both");
        const auto graph = cpm::routing::load_lane_graph_or_throw(parsed.get("--lanes"));
        cpm::routing::ConflictOptions spread;  // apart as central_routing keeps them (0.08 m), and 0.3 m more
        spread.margin = 0.08;
        const cpm::routing::ConflictTable table(graph, spread);
        const auto seed = uint64_t(cpm::cli::parse_integer("--seed", parsed.get("--seed", "1"), 0, 1ll << 53));
        for (const auto& p : cpm::routing::spread_cars(table, size_t(count), seed, 0.3)) poses.push_back(pose_text(p.x, p.y, p.yaw));
        return poses;
    }
    if (parsed.has("--seed")) throw cpm::cli::UsageError("cpm vehicle sim: --seed places cars on --lanes; give --lanes too");
    for (long long k = 0; k < count; ++k) {
        poses.push_back(pose_text(start.x - double(k) * spacing * std::cos(start.yaw), start.y - double(k) * spacing * std::sin(start.yaw),
                                  start.yaw));
    }
    return poses;
}

SimRequest read_request(const std::vector<std::string>& args)
{
    SimRequest r;
    r.parsed = cpm::cli::parse_flags(args,
                                     {{"--id", true}, {"--count", true}, {"--map", true}, {"--start", true},
                                      {"--spacing", true}, {"--params", true}, {"--calibration", true},
                                      {"--camera", true}, {"--camera-rate", true}, {"--lanes", true}, {"--seed", true},
                                      {"--process-per-car", false}, {"--firmware", true}, {"--truth_topic", true}},
                                     "cpm vehicle sim");
    const auto& parsed = r.parsed;
    const std::string firmware = parsed.get("--firmware", "sim");
    if (firmware != "sim" && firmware != "avr")
        throw cpm::cli::UsageError("cpm vehicle sim: --firmware is sim (firmware_sim) or avr (the AVR firmware in firmware_hil), not '" +
                                   firmware + "'");
    r.avr = firmware == "avr";
    // Every car in one simulator and one bridge process (a machine carries many more cars so),
    // or a simulator and a bridge for each (one car's crash is its own; an AVR chip is one car).
    r.per_car = parsed.has("--process-per-car") || r.avr;
    if (!parsed.has("--id")) throw cpm::cli::UsageError("cpm vehicle sim: --id is required (the vehicle id, 1..255)");
    r.first = cpm::cli::parse_integer("--id", parsed.get("--id"), 1, 255);
    r.count = cpm::cli::parse_integer("--count", parsed.get("--count", "1"), 1, 256 - r.first);
    if (parsed.has("--camera") && !parsed.has("--map")) {
        throw cpm::cli::UsageError("cpm vehicle sim: --camera needs --map (the world whose markers the camera sees)");
    }
    if (parsed.has("--camera")) cpm::aruco::Camera::load(parsed.get("--camera"));  // a wrong file fails here, not in a child
    r.simulated = std::find(parsed.init_args.begin(), parsed.init_args.end(), "--simulated_time") != parsed.init_args.end();
    r.camera_rate = parsed.get("--camera-rate", "30");
    cpm::cli::parse_number("--camera-rate", r.camera_rate, 0.1, 1000);
    r.poses = start_poses(parsed, r.count);
    return r;
}

/// The started cars: each group's microcontroller (firmware_sim or firmware_hil), bridge and
/// cameras in one process group, stopped in order (bridges first, so that none reports its
/// simulator's end as a lost link) on every way out, before the output copiers are joined.
class Fleet
{
public:
    explicit Fleet(const SimRequest& r)
        : r_(r), microcontroller_(r.avr ? "firmware_hil" : "firmware_sim"),
          microcontroller_path_(cpm::sibling_executable(microcontroller_)), bridge_path_(cpm::sibling_executable("vehicle_bridge")),
          camera_path_(r.parsed.has("--camera") ? cpm::sibling_executable("camera_sim") : "")
    {
    }
    ~Fleet()
    {
        (void)children_.stop_all();
        for (auto& t : copiers_) t.join();  // they end when their simulator does (its pipe closes)
    }
    Fleet(const Fleet&) = delete;
    Fleet& operator=(const Fleet&) = delete;

    /// Cars [begin, end) of the request in one simulator and one bridge process.
    void start_group(long long begin, long long end);
    /// The simulated-time node ids, for cpm lab clock.
    const std::string& timers() const { return timers_; }
    /// Until Ctrl-C or a child's end: 0, or 1 when a child failed.
    int supervise();

private:
    cpm::ChildProcess& launch(const std::string& name, std::vector<std::string> argv, bool capture);
    std::vector<std::string> read_devices(cpm::ChildProcess& sim, const std::string& name, const std::vector<std::string>& ids);
    void start_camera(const std::string& id);

    const SimRequest& r_;
    const std::string microcontroller_, microcontroller_path_, bridge_path_, camera_path_;
    cpm::ProcessGroup children_;
    std::vector<std::thread> copiers_;
    std::string timers_;
};

cpm::ChildProcess& Fleet::launch(const std::string& name, std::vector<std::string> argv, bool capture)
{
    argv.insert(argv.end(), r_.parsed.init_args.begin(), r_.parsed.init_args.end());
    const bool bridge = name.rfind("vehicle_bridge", 0) == 0;
    // In this command's process group: whoever stops or freezes it (Ctrl-C, Ctrl-Z, a lab run,
    // SIGSTOP) reaches its cars too.
    return children_.start(
        {.name = name, .argv = std::move(argv), .capture_stdout = capture, .stop_order = bridge ? 0 : 1, .own_process_group = false});
}

std::vector<std::string> Fleet::read_devices(cpm::ChildProcess& sim, const std::string& name, const std::vector<std::string>& ids)
{
    std::vector<std::string> devices;
    for (const auto& id : ids) {
        // "device: PATH" for one car, "device ID: PATH" for each of several
        const auto line = sim.read_line();
        const std::string prefix = ids.size() == 1 ? "device: " : "device " + id + ": ";
        if (!line) {
            const auto end = sim.wait(std::chrono::seconds(2));
            throw cpm::Error(microcontroller_ + " " + name + " did not start: it " + (end ? end->describe() : "closed its output") +
                             " before naming its device (its errors, if any, are above)");
        }
        if (line->rfind(prefix, 0) != 0) {
            throw cpm::Error(microcontroller_ + " " + name + " did not start: it printed '" + *line + "' where '" + prefix +
                             "PATH' was expected");
        }
        devices.push_back(line->substr(prefix.size()));
    }
    return devices;
}

void Fleet::start_camera(const std::string& id)
{
    cpm::ChildProcess& camera = launch("camera_sim " + id,
                                       {camera_path_, "--vehicle_id", id, "--camera", r_.parsed.get("--camera"), "--map",
                                        r_.parsed.get("--map"), "--rate", r_.camera_rate, "--truth_topic",
                                        r_.parsed.get("--truth_topic", "vehicleObservation")},
                                       false);
    std::printf("vehicle %s: camera_sim pid %d, %s Hz\n", id.c_str(), camera.pid(), r_.camera_rate.c_str());
    timers_ += "," + cpm::timer_ids::camera_sim(std::stoi(id));
}

void Fleet::start_group(long long begin, long long end)
{
    const auto& parsed = r_.parsed;
    std::vector<std::string> ids, starts;
    for (long long k = begin; k < end; ++k) {
        ids.push_back(std::to_string(r_.first + k));
        starts.push_back(r_.poses[size_t(k)]);
    }
    const std::string name = joined(ids, ",");
    std::vector<std::string> sim_argv{microcontroller_path_, "--vehicle_id", name, "--start", joined(starts, ";")};
    for (const char* flag : {"--map", "--params", "--truth_topic"}) {
        if (parsed.has(flag)) sim_argv.insert(sim_argv.end(), {flag, parsed.get(flag)});
    }
    cpm::ChildProcess& sim = launch(microcontroller_ + " " + name, sim_argv, true);
    timers_ += (timers_.empty() ? "" : ",") + cpm::vehicle::FirmwareSimNode::timer_name(uint8_t(std::stoi(ids[0]))) + "," +
               cpm::vehicle::BridgeNode::timer_name(uint8_t(std::stoi(ids[0])));
    const auto devices = read_devices(sim, name, ids);
    std::vector<std::string> bridge_argv{bridge_path_, "--vehicle_id", name, "--device", joined(devices, ","), "--start", joined(starts, ";")};
    if (parsed.has("--calibration")) bridge_argv.insert(bridge_argv.end(), {"--calibration", parsed.get("--calibration")});
    cpm::ChildProcess& bridge = launch("vehicle_bridge " + name, bridge_argv, false);
    for (size_t k = 0; k < ids.size(); ++k) {
        std::printf("vehicle %s: %s pid %d on %s, vehicle_bridge pid %d, start %s\n", ids[k].c_str(), microcontroller_.c_str(), sim.pid(),
                    devices[k].c_str(), bridge.pid(), starts[k].c_str());
        if (!camera_path_.empty()) start_camera(ids[k]);
    }
    std::fflush(stdout);
    copiers_.emplace_back([&sim] {
        while (auto l = sim.read_line()) {
            std::printf("%s\n", l->c_str());
            std::fflush(stdout);
        }
    });
}

int Fleet::supervise()
{
    int exit_code = 0;
    for (bool ended = false; !cpm::cli::stop_requested() && !ended;) {
        for (const auto& e : children_.poll()) {
            // Exit 0 unasked: the lab's clock stopped the timers (cpm lab clock), a normal end.
            std::fprintf(stderr, "cpm vehicle sim: %s %s%s; stopping the others\n", e.name.c_str(), e.end.describe().c_str(),
                         e.end.ok() ? " (the lab's clock stopped it)" : "");
            if (!e.end.ok()) exit_code = 1;
            ended = true;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    return exit_code;
}

int vehicle_sim(const std::vector<std::string>& args)
{
    const SimRequest request = read_request(args);
    cpm::cli::stop_on_signals();
    Fleet fleet(request);
    for (long long group = 0; group < (request.per_car ? request.count : 1); ++group) {
        fleet.start_group(request.per_car ? group : 0, request.per_car ? group + 1 : request.count);
    }
    if (request.simulated) {
        std::printf("simulated time: drive the cars with cpm lab clock --simulated --nodes %s[,your nodes]\n", fleet.timers().c_str());
        std::fflush(stdout);
    }
    return fleet.supervise();
}

}  // namespace

namespace cpm::tools {

std::vector<Command> vehicle_commands()
{
    return {{.group = "vehicle", .verb = "sim", .summary = "start simulated cars: firmware simulator + vehicle bridge over a pty", .help = kVehicleSimHelp, .run = vehicle_sim}};
}

}  // namespace cpm::tools
