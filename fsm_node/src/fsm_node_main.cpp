// fsm_node: runs a car's state machine against its VehicleState and RangeSensors (and
// ArucoMarkers when a camera publishes them) and commands it with VehicleCommandDirect.
// The work is cpm::fsm::FsmNode's.
#include <cpm/CommandLine.hpp>
#include <cpm/fsm/FsmNode.hpp>
#include <cpm/fsm/Loader.hpp>
#include <cpm/init.hpp>

#include <cstdio>
#include <cstdlib>
#include <string>

namespace {

const char* kHelp =
    "usage: fsm_node --vehicle_id N --fsm FILE.json|FILE.uxf [--rate 80] [--max-age 200ms] [--report] [--dds_domain N]\n"
    "                [--tick timer|on-sample] [--simulated_time]\n"
    "\n"
    "Loads and checks the state machine (all errors at once, exit 1), then looks at --rate Hz\n"
    "(cpm::Timer) for a new RangeSensors sample of vehicle N and ticks the machine once per\n"
    "sample (set the machine's tick_period to the sensors' period, 0.02 s for a bridge) against\n"
    "the newest valid VehicleState and RangeSensors (and\n"
    "ArucoMarkers, when present), writes VehicleCommandDirect for vehicle N, publishes FsmStatus\n"
    "on every state change and prints each transition. Stop states and missing or stale input\n"
    "(older than --max-age) brake the car with a StopRequest; the reason is logged. A StopRequest\n"
    "for this car (or for all) from anyone else (cpm monitor's stop button, a lab run's end) halts\n"
    "the machine: FsmStatus says StoppedByRequest and the car stays braked until fsm_node restarts.\n"
    "Ends on SIGINT/SIGTERM (braking the car) or when the machine stops in a final Stop state.\n"
    "--tick on-sample: tick as soon as a new RangeSensors sample arrives (0.4 ms from the sample to\n"
    "the command at the median here, as fast as a plain relay, instead of waiting for the timer's\n"
    "next look); --rate is then the watchdog that brakes on missing input. Real time only.\n"
    "--simulated_time: tick on the lab's simulated clock (timer fsm_node_N; cpm lab run, cpm lab\n"
    "clock --simulated), ages and times in lab time; a machine that stops frees the clock.\n"
    "--report: at the end, print the distance driven, the heading change and, for each wall\n"
    "following state, the followed range's mean and deviation from its clearance.\n";

int run(int argc, char** argv)
{
    auto parsed = cpm::cli::parse_flags(
        argc, argv, {{"--vehicle_id", true}, {"--fsm", true}, {"--rate", true}, {"--max-age", true}, {"--report", false}, {"--tick", true}},
        "fsm_node");
    if (!parsed.has("--vehicle_id")) throw cpm::cli::UsageError("fsm_node: --vehicle_id is required");
    if (!parsed.has("--fsm")) throw cpm::cli::UsageError("fsm_node: --fsm is required (a machine's JSON file)");
    cpm::fsm::FsmNodeOptions options;
    options.vehicle_id = static_cast<uint8_t>(cpm::cli::parse_integer("--vehicle_id", parsed.get("--vehicle_id"), 1, 255));
    options.rate_hz = cpm::cli::parse_number("--rate", parsed.get("--rate", "80"), 1, 1000);
    options.max_age_ns = cpm::cli::parse_duration("--max-age", parsed.get("--max-age", "200ms"));
    const std::string tick = parsed.get("--tick", "timer");
    if (tick != "timer" && tick != "on-sample") throw cpm::cli::UsageError("fsm_node: --tick '" + tick + "': expected timer or on-sample");
    options.tick_on_sample = tick == "on-sample";
    if (options.tick_on_sample && cpm::parse_init_settings(argc, argv, std::getenv("CPM_DOMAIN_ID")).simulated_time) {
        throw cpm::cli::UsageError("fsm_node: --tick on-sample and --simulated_time: the simulated clock steps the node's timer; "
                                   "tick on the timer (the default) in simulated time");
    }

    auto loaded = cpm::fsm::load_file(parsed.get("--fsm"));
    for (const auto& w : loaded.warnings) std::fprintf(stderr, "fsm_node: warning: %s\n", w.text().c_str());
    if (!loaded.ok()) {
        for (const auto& e : loaded.errors) std::fprintf(stderr, "fsm_node: error: %s\n", e.text().c_str());
        std::fprintf(stderr, "fsm_node: %zu error(s) in %s; not started\n", loaded.errors.size(), parsed.get("--fsm").c_str());
        return 1;
    }
    cpm::init(argc, argv);

    cpm::fsm::FsmNode node(options, std::move(loaded.machine), loaded.json);
    cpm::cli::stop_on_signals();
    // Said at once (the log is a file, fully buffered): a node that runs says so before it acts.
    std::printf("fsm_node: vehicle %u runs %s (%zu states, %zu transitions) from state %d (%s)\n", unsigned(options.vehicle_id),
                parsed.get("--fsm").c_str(), node.machine().states().size(), node.machine().transitions().size(), node.machine().active().id(),
                node.machine().active().type().c_str());
    std::fflush(stdout);
    node.run(cpm::cli::stop_requested);
    if (parsed.has("--report")) std::fputs(node.report().text().c_str(), stdout);
    std::printf("fsm_node: vehicle %u ended in state %d (%s)\n", unsigned(options.vehicle_id), node.machine().active().id(),
                node.machine().active().type().c_str());
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "fsm_node", kHelp, run); }
