// cpm routing check | render | simulate: lane graphs and the central planner, without DDS.
#include "Command.hpp"

#include <cpm/ReaderAbstract.hpp>
#include <cpm/routing/Render.hpp>
#include <cpm/routing/Simulate.hpp>
#include <cpm/routing/TrafficWatch.hpp>
#include <cpm/topics.hpp>

#include <VehicleObservation.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <set>
#include <thread>

namespace cpm::tools {
namespace {

const char* kRoutingCheckHelp =
    "usage: cpm routing check FILE.json\n"
    "\n"
    "Loads a lane graph as central_routing does and prints every error with its JSON path\n"
    "(missing nodes, edges whose ends miss their nodes by more than 1 cm, points more than 5 cm\n"
    "apart, nodes with no way out, edges on no cycle); when it is sound, its size and conflict\n"
    "zones for the simulator's 1:10 cars with a 5 cm margin. Exit code 1 on errors.\n";

const char* kRenderHelp =
    "usage: cpm routing render FILE.json --out MAP.svg|MAP.png [--margin M]\n"
    "\n"
    "Draws a lane graph: lanes with an arrow for their direction, node ids, and the conflict\n"
    "zones (red) for the simulator's 1:10 cars with the margin (default 0.05 m).\n";

const char* kSimulateHelp =
    "usage: cpm routing simulate --lanes FILE --vehicles N --duration T [--seed S] [--mode M]\n"
    "                            [--period P] [--margin M] [--v-max V] [--start-gap G] [--json]\n"
    "                            [--picture OUT.svg|OUT.png]\n"
    "\n"
    "Runs the central planner against ideal cars that follow their plans exactly (no DDS, as\n"
    "fast as it can), N cars placed by the seed, for T of simulated time (e.g. 60s), and prints\n"
    "one summary: vehicles, duration_s, collisions, min_distance_m (between bodies, every 20 ms),\n"
    "max_wait_s (longest standstill), stalled (a car stood over 10 s), distance_m (per car),\n"
    "throughput_per_min (cars into the busiest conflict zone), plan_ms_p50, plan_ms_p99.\n"
    "--mode cooperative (default) or cpm_lab (cpm_lab's fixed-priority speed capping, the\n"
    "baseline). --period defaults to 400ms, --margin to 0.05 m, --v-max to 1.0 m/s; the cars start\n"
    "outside conflict zones, their bodies at least the margin and --start-gap (0.1 m) apart.\n"
    "--json prints the summary as one JSON line; --picture draws the cars where they ended.\n";

const char* kWatchHelp =
    "usage: cpm routing watch --duration T [--vehicles 1,2,…] [--lanes FILE --picture OUT.svg|OUT.png]\n"
    "\n"
    "Watches the cars' true poses (vehicleObservation, from the simulator or the lab's positioning\n"
    "system) for T (e.g. 60s) of lab time, and prints how far each drove, its longest standstill,\n"
    "and the smallest distance between two cars' bodies (the simulator's 1:10 car). Lab time is\n"
    "the observations' own clock: real time, or the simulated clock that `cpm lab clock\n"
    "--simulated` drives (then T passes as fast as the lab computes); the watch also ends when\n"
    "the observations stop for 3 s. --vehicles limits it to those ids. --picture draws the lane\n"
    "graph with the cars where they were last seen.\n"
    "Exit code 1 when two cars touched, or when a listed car was never seen.\n";

/// Loads a graph, printing its errors; nullopt when it has any.
std::optional<cpm::routing::LaneGraph> load_graph(const std::string& file)
{
    auto loaded = cpm::routing::load_lane_graph(file);
    for (const auto& e : loaded.errors) std::fprintf(stderr, "error: %s\n", e.text().c_str());
    if (!loaded.ok()) {
        std::fprintf(stderr, "%s: %zu error(s)\n", file.c_str(), loaded.errors.size());
        return std::nullopt;
    }
    return std::move(*loaded.value);
}

int routing_check(const std::vector<std::string>& args)
{
    const std::string file = only_positional(parse_args(args, {}, "cpm routing check"), "cpm routing check", "lane graph file");
    auto graph = load_graph(file);
    if (!graph) return 1;
    const auto t0 = std::chrono::steady_clock::now();
    cpm::routing::ConflictTable table(*graph, {});
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    std::printf("%s: ok (%zu nodes, %zu edges, %.1f m of lanes, %zu conflict zones, computed in %.0f ms)\n", file.c_str(),
                graph->nodes.size(), graph->edges.size(), graph->total_length(), table.zones().size(), ms);
    return 0;
}

int routing_render(const std::vector<std::string>& args)
{
    const auto parsed = parse_args(args, {{"--out", true}, {"--margin", true}}, "cpm routing render");
    const std::string file = only_positional(parsed, "cpm routing render", "lane graph file");
    if (!parsed.has("--out")) throw UsageError("cpm routing render: --out MAP.svg|MAP.png is required");
    cpm::routing::ConflictOptions options;
    if (parsed.has("--margin")) options.margin = cpm::cli::parse_number("--margin", parsed.get("--margin"), 0, 1);
    auto graph = load_graph(file);
    if (!graph) return 1;
    cpm::routing::ConflictTable table(*graph, options);
    cpm::routing::render_lane_graph(table, parsed.get("--out"));
    std::printf("%s: drawn to %s (%zu conflict zones)\n", file.c_str(), parsed.get("--out").c_str(), table.zones().size());
    return 0;
}

int routing_simulate(const std::vector<std::string>& args)
{
    const auto parsed = parse_flags(args,
                                    {{"--lanes", true}, {"--vehicles", true}, {"--duration", true}, {"--seed", true},
                                     {"--mode", true}, {"--period", true}, {"--margin", true}, {"--v-max", true}, {"--start-gap", true},
                                     {"--json", false}, {"--picture", true}},
                                    "cpm routing simulate");
    for (const char* required : {"--lanes", "--vehicles", "--duration"}) {
        if (!parsed.has(required)) throw UsageError(std::string("cpm routing simulate: ") + required + " is required");
    }
    cpm::routing::SimulationOptions options;
    options.vehicles = size_t(cpm::cli::parse_integer("--vehicles", parsed.get("--vehicles"), 1, 200));
    options.duration = double(parse_duration("--duration", parsed.get("--duration"))) * 1e-9;
    if (options.duration <= 0) throw UsageError("cpm routing simulate: --duration " + parsed.get("--duration") + ": must be positive");
    if (parsed.has("--period")) {
        options.period = double(parse_duration("--period", parsed.get("--period"))) * 1e-9;
        const double steps = options.period / options.planner.dt;
        if (options.period <= 0 || std::abs(steps - std::round(steps)) > 1e-6) {
            throw UsageError("cpm routing simulate: --period " + parsed.get("--period") + ": must be a positive multiple of 50ms");
        }
    }
    if (parsed.has("--seed")) options.planner.seed = uint64_t(cpm::cli::parse_integer("--seed", parsed.get("--seed"), 0, 1ll << 53));
    if (parsed.has("--margin")) options.planner.margin = cpm::cli::parse_number("--margin", parsed.get("--margin"), 0, 1);
    if (parsed.has("--start-gap")) options.start_gap = cpm::cli::parse_number("--start-gap", parsed.get("--start-gap"), 0, 10);
    if (parsed.has("--v-max")) options.planner.v_max = cpm::cli::parse_number("--v-max", parsed.get("--v-max"), 0.1, 3);
    if (parsed.has("--mode")) {
        auto mode = cpm::routing::mode_from_string(parsed.get("--mode"));
        if (!mode) throw UsageError("cpm routing simulate: --mode " + parsed.get("--mode") + ": expected cooperative or cpm_lab");
        options.planner.mode = *mode;
    }
    auto graph = load_graph(parsed.get("--lanes"));
    if (!graph) return 1;
    const auto summary = cpm::routing::simulate(*graph, options);
    if (parsed.has("--picture")) {
        cpm::routing::ConflictTable table(*graph, {});
        std::vector<cpm::routing::DrawnCar> cars;
        for (const auto& [id, pose] : summary.final_poses) cars.push_back({id, pose});
        cpm::routing::render_lane_graph(table, parsed.get("--picture"), cars);
    }
    if (parsed.has("--json")) {
        std::printf("%s\n", summary.to_json().c_str());
        return 0;
    }
    std::printf("vehicles            %zu (%s)\n", summary.vehicles, cpm::routing::to_string(options.planner.mode));
    std::printf("duration            %.1f s\n", summary.duration_s);
    std::printf("collisions          %zu\n", summary.collisions);
    std::printf("min distance        %.3f m\n", summary.min_distance_m);
    std::printf("longest standstill  %.2f s%s\n", summary.max_wait_s, summary.stalled ? "  (stalled)" : "");
    double total = 0;
    for (double d : summary.distance_m) total += d;
    std::printf("distance            %.1f m in all, %.1f m per car\n", total, total / double(summary.vehicles));
    std::printf("throughput          %.1f cars/min through the busiest conflict zone\n", summary.throughput_per_min);
    std::printf("planning            p50 %.2f ms, p99 %.2f ms per cycle\n", summary.plan_ms_p50, summary.plan_ms_p99);
    if (summary.stalled && options.planner.mode == cpm::routing::Mode::cooperative) {
        const double least = *std::min_element(summary.distance_m.begin(), summary.distance_m.end());
        std::printf("stalled: a car stood still for over 10 s. On a small map with many cars a car can wait\n"
                    "long for a zone the others' plans keep claiming; the car that drove least drove %.1f m\n"
                    "(near 0: locked in). Try fewer cars.\n", least);
        if (!parsed.has("--picture")) std::printf("--picture OUT.png shows where they stood.\n");
    }
    if (parsed.has("--picture")) std::printf("the cars where they ended: %s\n", parsed.get("--picture").c_str());
    return 0;
}

int routing_watch(const std::vector<std::string>& args)
{
    const auto parsed = parse_flags(args, {{"--duration", true}, {"--vehicles", true}, {"--lanes", true}, {"--picture", true}},
                                    "cpm routing watch");
    if (!parsed.has("--duration")) throw UsageError("cpm routing watch: --duration is required (e.g. 60s)");
    if (parsed.has("--picture") != parsed.has("--lanes")) throw UsageError("cpm routing watch: --picture needs --lanes, and --lanes is only for --picture");
    const uint64_t duration = parse_duration("--duration", parsed.get("--duration"));
    std::set<int> only;
    if (parsed.has("--vehicles")) {
        for (const auto& id : split_list("--vehicles", parsed.get("--vehicles"))) only.insert(int(cpm::cli::parse_integer("--vehicles", id, 1, 255)));
    }
    std::optional<cpm::routing::LaneGraph> graph;
    if (parsed.has("--lanes")) {
        graph = load_graph(parsed.get("--lanes"));
        if (!graph) return 1;
    }
    cpm::ReaderAbstract<VehicleObservation> poses(cpm::topics::vehicle_observation.name, {.keep_all = true});
    cpm::routing::TrafficWatch watch(cpm::routing::Footprint::of(cpm::vehicle::VehicleParameters{}));
    cpm::cli::stop_on_signals();
    // T is counted on the observations' clock (simulated time may run faster than real time);
    // a lab that never starts is not waited for beyond T of real time and 10 s more.
    using Clock = std::chrono::steady_clock;
    const auto give_up = Clock::now() + std::chrono::nanoseconds(duration) + std::chrono::seconds(10);
    auto last_arrival = Clock::now();
    uint64_t first = 0, newest = 0;
    bool stopped = false;
    while (!cpm::cli::stop_requested()) {
        for (const auto& o : poses.take()) {
            if (!only.empty() && !only.count(o.vehicle_id())) continue;
            const uint64_t stamp = o.header().create_stamp().nanoseconds();
            watch.add(o.vehicle_id(), stamp, {o.pose().x(), o.pose().y(), o.pose().yaw()});
            if (first == 0) first = stamp;
            newest = std::max(newest, stamp);
            last_arrival = Clock::now();
        }
        if (first != 0 && newest - first >= duration) break;
        if (first != 0 && Clock::now() - last_arrival > std::chrono::seconds(3)) {
            stopped = true;
            break;
        }
        if (first == 0 && Clock::now() > give_up) break;
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    std::printf("watched %.1f s of lab time%s\n", double(newest - first) * 1e-9,
                stopped ? " (then the observations stopped for 3 s)" : "");
    std::fputs(watch.report().c_str(), stdout);
    bool missing = false;
    for (int id : only) {
        if (!watch.cars().count(id)) {
            std::printf("vehicle %d: never seen\n", id);
            missing = true;
        }
    }
    if (graph) {
        cpm::routing::ConflictTable table(*graph, {});
        std::vector<cpm::routing::DrawnCar> cars;
        for (const auto& [id, c] : watch.cars()) cars.push_back({id, c.last});
        cpm::routing::render_lane_graph(table, parsed.get("--picture"), cars);
        std::printf("the cars where they were last seen: %s\n", parsed.get("--picture").c_str());
    }
    return watch.overlaps() > 0 || missing ? 1 : 0;
}

}  // namespace

std::vector<Command> routing_commands()
{
    return {{.group = "routing", .verb = "check", .summary = "check a lane graph file and count its conflict zones", .help = kRoutingCheckHelp, .run = routing_check},
            {.group = "routing", .verb = "render", .summary = "draw a lane graph with its conflict zones (SVG or PNG)", .help = kRenderHelp, .run = routing_render},
            {.group = "routing", .verb = "simulate", .summary = "run the central planner against ideal cars and summarise", .help = kSimulateHelp, .run = routing_simulate},
            {.group = "routing", .verb = "watch", .summary = "watch the cars' true poses: distance driven, standstills, closest bodies", .help = kWatchHelp, .run = routing_watch}};
}

}  // namespace cpm::tools
