// cpm host run|clock: the far side of a lab run's ssh to another host (the work is in
// cpm/RemoteHost.hpp). A lab run calls these; a user rarely does.
#include "Command.hpp"

#include <cpm/RemoteHost.hpp>

#include <cstdio>

namespace cpm::tools {
namespace {

const char* kRunHelp =
    "usage: cpm host run [--grace DURATION] [--lease DURATION] -- PROGRAM [ARGS...]\n"
    "\n"
    "Runs PROGRAM in a process group of its own, with this command's output, until it ends or\n"
    "this command's input ends; then stops it: SIGINT, and SIGTERM and SIGKILL --grace apart\n"
    "(default 5s). Exits with its exit code, or 128 + the signal that ended it. A lab run starts\n"
    "each process on another host this way over ssh, so that closing the connection (the run\n"
    "stops, dies, or loses the host) stops the process and everything it started. With --lease,\n"
    "input silent for that long stops it too: a lab run writes a line every second, so a host cut\n"
    "off from the run (where the connection may look open for hours) stops the run's processes.\n"
    "\n"
    "Example: cpm host run --grace 2s -- /opt/cpm/bin/fsm_node --vehicle_id 5 --fsm car.json\n";

const char* kClockHelp =
    "usage: cpm host clock\n"
    "\n"
    "Answers each line of its input with this host's clock (CLOCK_REALTIME) in nanoseconds, until\n"
    "its input ends. A lab run measures each host's clock offset with it before it starts.\n";

const char* kPortsHelp =
    "usage: cpm host ports PROTOCOL:PORT...\n"
    "\n"
    "Whether each port (tcp:8080, udp:11811) can be taken on this host: prints one line per port\n"
    "that cannot (`tcp:8080 Address already in use`) and exits 1; exits 0 silently when all are\n"
    "free. A lab run asks each host for the ports its processes there will listen on.\n";

int host_ports(const std::vector<std::string>& args)
{
    const auto parsed = cpm::cli::parse_args(args, {}, "cpm host ports");
    if (parsed.positional.empty()) throw UsageError("cpm host ports: expected PROTOCOL:PORT (e.g. tcp:8080)");
    int taken = 0;
    for (const auto& p : parsed.positional) {
        const auto colon = p.find(':');
        const std::string protocol = p.substr(0, colon);
        if (colon == std::string::npos || (protocol != "tcp" && protocol != "udp"))
            throw UsageError("cpm host ports: '" + p + "' is not PROTOCOL:PORT with tcp or udp (e.g. tcp:8080)");
        const int port = int(cpm::cli::parse_integer("port of " + p, p.substr(colon + 1), 1, 65535));
        if (const std::string why = cpm::port_taken(protocol, port); !why.empty()) {
            std::printf("%s %s\n", p.c_str(), why.c_str());
            ++taken;
        }
    }
    return taken == 0 ? 0 : 1;
}

int host_run(const std::vector<std::string>& args)
{
    const std::string command = "cpm host run";
    const auto split = std::find(args.begin(), args.end(), "--");
    if (split == args.end() || split + 1 == args.end()) throw UsageError(command + ": expected -- PROGRAM [ARGS...]");
    const auto parsed = parse_flags(std::vector<std::string>(args.begin(), split), {{"--grace", true}, {"--lease", true}}, command);
    const auto grace_ns = parsed.has("--grace") ? parse_duration("--grace", parsed.get("--grace")) : 5'000'000'000ull;
    const auto lease_ns = parsed.has("--lease") ? parse_duration("--lease", parsed.get("--lease")) : 0ull;
    return cpm::run_until_input_ends(std::vector<std::string>(split + 1, args.end()), std::chrono::milliseconds(grace_ns / 1'000'000),
                                     std::chrono::milliseconds(lease_ns / 1'000'000));
}

int host_clock(const std::vector<std::string>& args)
{
    (void)parse_flags(args, {}, "cpm host clock");
    cpm::answer_clock_queries();
    return 0;
}

}  // namespace

std::vector<Command> host_commands()
{
    return {{.group = "host", .verb = "run", .summary = "run a program tied to this command's input (a lab run's remote processes)",
             .help = kRunHelp, .run = host_run},
            {.group = "host", .verb = "clock", .summary = "answer clock queries (a lab run measures each host's clock offset)",
             .help = kClockHelp, .run = host_clock},
            {.group = "host", .verb = "ports", .summary = "tell which ports cannot be taken here (a lab run asks each host)",
             .help = kPortsHelp, .run = host_ports}};
}

}  // namespace cpm::tools
