// cpm monitor: the lab live in a browser (the work is in cpm::monitor).
#include "Command.hpp"

#include <cpm/Participant.hpp>
#include <cpm/monitor/Monitor.hpp>

#include <chrono>
#include <cstdio>
#include <thread>

namespace cpm::tools {
namespace {

const char* kMonitorHelp =
    "usage: cpm monitor [--port 8080] [--bind 127.0.0.1] [--world FILE] [--lanes FILE] [--allow-stop]\n"
    "                   [--dds_domain N]\n"
    "\n"
    "Serves the lab live to a browser until Ctrl-C: the map (walls, lanes, markers, gates) with every\n"
    "car at its pose, its id and FSM state; a panel per car (speed, steering, ranges, battery, FSM\n"
    "state and since when, age of its newest sample); speed and distance to the nearest wall or car\n"
    "over the last 30 s; the topics with their rates; the newest log lines. It works the same with\n"
    "a live lab and with `cpm play` of a recording (the page says which).\n"
    "\n"
    "  --port N       the port (default 8080; 0: any free port, printed at start)\n"
    "  --bind ADDR    the address to listen on (default 127.0.0.1, this host only); any other\n"
    "                 address lets everyone on that network watch, and is warned about\n"
    "  --world FILE   the world file whose walls, markers and gates are drawn\n"
    "  --lanes FILE   the lane graph to draw\n"
    "  --allow-stop   enable the stop buttons (a StopRequest per car, or for all); off by default\n"
    "\n"
    "HTTP: GET / (the page), GET /api/state (JSON), GET /api/stream (server-sent events of the same),\n"
    "GET /api/world, GET /api/plots, POST /api/stop {\"vehicle_id\": N} (0: every car).\n";

int monitor(const std::vector<std::string>& args)
{
    const std::string command = "cpm monitor";
    const auto parsed = parse_flags(args,
                                    {{"--port", true}, {"--bind", true}, {"--world", true}, {"--lanes", true}, {"--allow-stop", false}},
                                    command);
    cpm::monitor::MonitorOptions options;
    if (parsed.has("--port")) options.port = int(cpm::cli::parse_integer(command + ": --port", parsed.get("--port"), 0, 65535));
    options.bind = parsed.get("--bind", options.bind);
    options.world = parsed.get("--world");
    options.lanes = parsed.get("--lanes");
    options.allow_stop = parsed.has("--allow-stop");
    const std::string warning = cpm::monitor::bind_warning(options.bind, options.allow_stop);
    if (!warning.empty()) std::fprintf(stderr, "%s\n", warning.c_str());

    cpm::cli::stop_on_signals();
    // Named cpm_monitor (unless --node_id names it): a lab run lets watchers stay on its domain.
    cpm::Participant participant(named_participant("cpm_monitor"));
    cpm::monitor::Monitor server(participant, options);
    std::printf("cpm monitor: serving the lab of domain %d at %s%s\n", participant.domain_id(), server.address().c_str(),
                options.allow_stop ? " (stop buttons on)" : "");
    std::fflush(stdout);
    while (!cpm::cli::stop_requested()) std::this_thread::sleep_for(std::chrono::milliseconds(50));
    return 0;
}

}  // namespace

std::vector<Command> monitor_commands()
{
    return {{.group = "monitor", .verb = "", .summary = "serve the lab live to a browser (map, cars, plots, topics, log)", .help = kMonitorHelp, .run = monitor}};
}

}  // namespace cpm::tools
