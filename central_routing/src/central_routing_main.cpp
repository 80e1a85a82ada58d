// central_routing: plans collision-free trajectories for many cars on a lane graph and sends
// each its VehicleCommandTrajectory. The work is cpm::routing::RoutingNode's.
#include <cpm/CommandLine.hpp>
#include <cpm/init.hpp>
#include <cpm/routing/RoutingNode.hpp>

#include <cmath>
#include <cstdio>
#include <string>

namespace {

const char* kHelp =
    "usage: central_routing --vehicle_ids 1,2,… --lanes FILE.json [--seed S] [--period 400ms]\n"
    "                       [--mode cooperative|cpm_lab] [--margin 0.08] [--v-max 1.0]\n"
    "                       [--no-wait-for-start] [--dds_domain N] [--simulated_time]\n"
    "\n"
    "Plans every listed car's motion on the lane graph (checked first: every error with its JSON\n"
    "path, exit 1) so that no two bodies come closer than --margin metres (default 0.08: real cars\n"
    "follow their trajectories to a few centimetres, and the margin has to hold that), and sends\n"
    "each car a VehicleCommandTrajectory every period reaching 8 s ahead (it ends at standstill).\n"
    "Routes are random walks from the seed. Cars are placed on the graph from their VehicleState\n"
    "when they appear (a car on no lane is logged with its pose and left out); a car whose state is\n"
    "older than 1 s is dropped from planning (the others keep clear of where it was last seen)\n"
    "and taken back when it returns. The first plan waits up to 3 s for every listed car.\n"
    "The timer waits for the lab's start signal (`cpm lab clock`) unless --no-wait-for-start;\n"
    "with --simulated_time it follows the lab's simulated clock. Ends on SIGINT/SIGTERM and prints\n"
    "its statistics as one JSON line.\n";

int run(int argc, char** argv)
{
    auto parsed = cpm::cli::parse_flags(argc, argv,
                                        {{"--vehicle_ids", true}, {"--lanes", true}, {"--seed", true}, {"--period", true},
                                         {"--mode", true}, {"--margin", true}, {"--v-max", true}, {"--no-wait-for-start", false}},
                                        "central_routing");
    if (!parsed.has("--vehicle_ids")) throw cpm::cli::UsageError("central_routing: --vehicle_ids is required (e.g. 1,2,3)");
    if (!parsed.has("--lanes")) throw cpm::cli::UsageError("central_routing: --lanes is required (a lane graph JSON file)");
    cpm::routing::RoutingNodeOptions options;
    for (const auto& id : cpm::cli::split_list("--vehicle_ids", parsed.get("--vehicle_ids"))) {
        options.vehicle_ids.push_back(uint8_t(cpm::cli::parse_integer("--vehicle_ids", id, 1, 255)));
    }
    options.period_ns = cpm::cli::parse_duration("--period", parsed.get("--period", "400ms"));
    const double steps = double(options.period_ns) * 1e-9 / options.planner.dt;
    if (options.period_ns == 0 || std::abs(steps - std::round(steps)) > 1e-6) {
        throw cpm::cli::UsageError("central_routing: --period " + parsed.get("--period") + ": must be a positive multiple of 50ms");
    }
    options.planner.seed = uint64_t(cpm::cli::parse_integer("--seed", parsed.get("--seed", "1"), 0, 1ll << 53));
    options.planner.margin = cpm::cli::parse_number("--margin", parsed.get("--margin", "0.08"), 0, 1);
    options.planner.v_max = cpm::cli::parse_number("--v-max", parsed.get("--v-max", "1.0"), 0.1, 3);
    if (parsed.has("--mode")) {
        auto mode = cpm::routing::mode_from_string(parsed.get("--mode"));
        if (!mode) throw cpm::cli::UsageError("central_routing: --mode " + parsed.get("--mode") + ": expected cooperative or cpm_lab");
        options.planner.mode = *mode;
    }
    options.wait_for_start = !parsed.has("--no-wait-for-start");
    auto loaded = cpm::routing::load_lane_graph(parsed.get("--lanes"));
    if (!loaded.ok()) {
        for (const auto& e : loaded.errors) std::fprintf(stderr, "central_routing: error: %s\n", e.text().c_str());
        std::fprintf(stderr, "central_routing: %zu error(s) in %s; not started\n", loaded.errors.size(), parsed.get("--lanes").c_str());
        return 1;
    }
    cpm::init(argc, argv);
    cpm::routing::RoutingNode node(*loaded.value, options);
    return cpm::cli::run_node(node);
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "central_routing", kHelp, run); }
