// hlc_middleware: between a user's high-level controller and the lab. The work is
// cpm::hlc::Middleware's.
#include <cpm/CommandLine.hpp>
#include <cpm/hlc/Middleware.hpp>
#include <cpm/init.hpp>

#include <string>

namespace {

const char* kHelp =
    "usage: hlc_middleware --vehicle_ids 1,2,… --controller_domain N [--name NAME] [--period 100ms]\n"
    "                      [--answer_timeout 10s] [--controller_wait 30s] [--no-wait-for-start]\n"
    "                      [--dds_domain N] [--simulated_time]\n"
    "\n"
    "Every period of the lab clock (the lab on --dds_domain) writes the controller's\n"
    "VehicleStateList — the newest valid vehicleState and vehicleObservation of each listed car —\n"
    "on vehicleStateList in the controller's own domain (--controller_domain, this host only), and\n"
    "forwards the controller's commands (vehicleCommandDirect, …SpeedCurvature, …Trajectory,\n"
    "…PathTracking) to the lab after checking each: a car not listed, a create_stamp in the future\n"
    "or before the newest list's t_now (a period already past), or a value the car's bridge would\n"
    "refuse is not forwarded, but counted and logged with the reason. The controller answers a\n"
    "period with cpm::hlc::Communicator; each period's response time is measured. With\n"
    "--simulated_time a period waits for the answer (at most --answer_timeout of real time), so\n"
    "the controller holds the lab clock while it computes. The start waits up to --controller_wait\n"
    "for the controller to announce itself. Relays the lab's stop to the controller. Ends on\n"
    "SIGINT/SIGTERM or the lab's stop and prints its statistics as one JSON line (periods,\n"
    "answered, unanswered, response_ms_p50/p99, forwarded, refused by reason).\n";

int run(int argc, char** argv)
{
    auto parsed = cpm::cli::parse_flags(argc, argv,
                                        {{"--vehicle_ids", true}, {"--controller_domain", true}, {"--name", true}, {"--period", true},
                                         {"--answer_timeout", true}, {"--controller_wait", true}, {"--no-wait-for-start", false}},
                                        "hlc_middleware");
    if (!parsed.has("--vehicle_ids")) throw cpm::cli::UsageError("hlc_middleware: --vehicle_ids is required (e.g. 1,2,3)");
    if (!parsed.has("--controller_domain")) throw cpm::cli::UsageError("hlc_middleware: --controller_domain is required (0..232)");
    cpm::hlc::MiddlewareOptions o;
    for (const auto& id : cpm::cli::split_list("--vehicle_ids", parsed.get("--vehicle_ids"))) {
        o.vehicle_ids.push_back(uint8_t(cpm::cli::parse_integer("--vehicle_ids", id, 1, 255)));
    }
    o.controller_domain = int(cpm::cli::parse_integer("--controller_domain", parsed.get("--controller_domain"), 0, 232));
    o.name = parsed.get("--name", "hlc");
    o.period_ns = cpm::cli::parse_duration("--period", parsed.get("--period", "100ms"));
    if (o.period_ns < 1'000'000) throw cpm::cli::UsageError("hlc_middleware: --period " + parsed.get("--period") + ": at least 1ms");
    o.answer_timeout = std::chrono::milliseconds(cpm::cli::parse_duration("--answer_timeout", parsed.get("--answer_timeout", "10s")) / 1'000'000);
    o.controller_wait = std::chrono::milliseconds(cpm::cli::parse_duration("--controller_wait", parsed.get("--controller_wait", "30s")) / 1'000'000);
    o.wait_for_start = !parsed.has("--no-wait-for-start");
    cpm::init(argc, argv);
    cpm::hlc::Middleware node(o);
    return cpm::cli::run_node(node);
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "hlc_middleware", kHelp, run); }
