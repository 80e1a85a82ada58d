// cpm — the lab's command line, in the style of `ros2`:
//   cpm lab clock --nodes a,b,c [--simulated --until 10s | --start-delay 1s --duration 60s]
// Errors go to stderr with the reason, and the exit code is non-zero.
#include "history.hpp"
#include "vehicle_sim.hpp"

#include <cpm/CommandLine.hpp>
#include <cpm/Error.hpp>
#include <cpm/ParameterServer.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/TimeMaster.hpp>
#include <cpm/fsm/Loader.hpp>
#include <cpm/fsm/Render.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/init.hpp>

#include <Log.h>

#include <nlohmann/json.hpp>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <sys/wait.h>

namespace {

using cpm::cli::FlagSpec;
using cpm::cli::ParsedArgs;
using cpm::cli::UsageError;
using cpm::cli::parse_args;
using cpm::cli::parse_duration;
using cpm::cli::split_list;
constexpr int kUsageError = cpm::cli::kUsageExit;

const char* kTopHelp =
    "usage: cpm COMMAND ...\n"
    "\n"
    "  lab clock    drive the lab's timers: a synchronised real-time start and stop, or a\n"
    "               simulated clock (see `cpm lab clock --help`)\n"
    "  param serve  serve the parameters of a JSON file until Ctrl-C (see `cpm param serve --help`)\n"
    "  topic echo   print a topic's samples as they arrive (see `cpm topic echo --help`)\n"
    "  fsm check    check a state machine file (.json or UMLet .uxf): every error and warning\n"
    "  fsm convert  print a UMLet drawing's state machine as JSON\n"
    "  fsm render   draw a state machine with Graphviz (-o OUT.svg|png|dot)\n"
    "  history ...  ask the history service about the recent past: list, search, latest, at,\n"
    "               older, younger, range, wait, successor, snapshot (see `cpm history --help`)\n"
    "  dump         one table of every object the history service holds\n"
    "  vehicle sim  start simulated cars: firmware simulator + vehicle bridge over a pty\n"
    "               (see `cpm vehicle sim --help`)\n"
    "\n"
    "Every command takes --dds_domain N (or CPM_DOMAIN_ID) and answers --help.\n";

const char* kClockHelp =
    "usage: cpm lab clock --nodes ID[,ID...] [--simulated --until DURATION]\n"
    "                     [--start-delay DURATION] [--duration DURATION] [--dds_domain N]\n"
    "\n"
    "Real time (default): waits until every named node's timer announced it is ready, sends the\n"
    "start (now + --start-delay, default 1s), runs for --duration (default: until Ctrl-C), then\n"
    "stops every timer.\n"
    "Simulated (--simulated): drives the lab clock from 0 to --until through the nodes' announced\n"
    "ticks as fast as they compute, then stops every timer. Nodes must run with --simulated_time.\n"
    "DURATION: a number with ns, us, ms, s, m or h (e.g. 500ms, 10s).\n";

const char* kParamHelp =
    "usage: cpm param serve FILE.json [--dds_domain N]\n"
    "\n"
    "Serves the file's parameters on topic 'parameter' and answers 'parameterRequest' until\n"
    "Ctrl-C. FILE: {\"name\": value, ...} with the type taken from the value, or\n"
    "{\"name\": {\"type\": \"bool|int|uint64|double|string|ints|doubles\", \"value\": ...}}.\n";

const char* kFsmCheckHelp =
    "usage: cpm fsm check FILE.json\n"
    "\n"
    "Loads and checks a state machine as fsm_node would, and prints every error and warning with\n"
    "its file and JSON path. Exit code 0 when it has no errors (warnings allowed), 1 otherwise.\n"
    "The state and transition types and their parameters: fsm_node/README.md.\n";

const char* kFsmConvertHelp =
    "usage: cpm fsm convert FILE.uxf\n"
    "\n"
    "Prints the state machine of a UMLet drawing as JSON (the format fsm_node reads), after the\n"
    "same check as `cpm fsm check`; errors name the drawing's element. Exit code 1 on errors.\n";

const char* kFsmRenderHelp =
    "usage: cpm fsm render FILE.json|FILE.uxf -o|--output OUT.svg|OUT.png|OUT.dot\n"
    "\n"
    "Draws a checked state machine with Graphviz (`dot`, Debian package graphviz): states as\n"
    "boxes with id, type and parameters (the root bold, final states double-framed),\n"
    "transitions as arrows labelled with id, type and condition. Exit code 1 on errors.\n";

const char* kEchoHelp =
    "usage: cpm topic echo log [--json] [--count N] [--timeout DURATION] [--dds_domain N]\n"
    "\n"
    "Prints the lab's log messages (topic 'log', including the recent ones sent before it started)\n"
    "as they arrive: a table for people, or one JSON object per line with --json. Stops after N\n"
    "messages or after --timeout without one, else on Ctrl-C. Other topics: not yet.\n";

// The single positional argument a command takes (`what` names it in the error).
std::string only_positional(const ParsedArgs& parsed, const std::string& command, const std::string& what)
{
    if (parsed.positional.empty()) throw UsageError(command + ": no " + what + " given (see --help)");
    if (parsed.positional.size() > 1) {
        throw UsageError(command + ": unexpected argument '" + parsed.positional[1] + "'");
    }
    return parsed.positional[0];
}

int lab_clock(const std::vector<std::string>& args)
{
    const auto parsed = parse_args(
        args, {{"--nodes", true}, {"--simulated", false}, {"--until", true}, {"--start-delay", true}, {"--duration", true}},
        "cpm lab clock");
    if (!parsed.positional.empty()) {
        throw UsageError("cpm lab clock: unexpected argument '" + parsed.positional[0] + "'");
    }
    const auto& flags = parsed.flags;
    if (!flags.count("--nodes")) throw UsageError("cpm lab clock: --nodes is required (the timers' node ids)");
    const auto nodes = split_list("--nodes", flags.at("--nodes"));
    cpm::Participant participant;
    cpm::TimeMaster master(participant);

    if (flags.count("--simulated")) {
        if (!flags.count("--until")) throw UsageError("cpm lab clock --simulated: --until is required");
        const uint64_t until = parse_duration("--until", flags.at("--until"));
        const auto t0 = std::chrono::steady_clock::now();
        const uint64_t steps = master.run_simulated(nodes, until);
        const double real = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        std::printf("simulated %.3f s in %.3f real s (%llu steps, %.1fx real time); stopped all timers\n",
                    double(until) * 1e-9, real, static_cast<unsigned long long>(steps),
                    real > 0 ? double(until) * 1e-9 / real : 0.0);
        return 0;
    }
    const uint64_t delay = flags.count("--start-delay") ? parse_duration("--start-delay", flags.at("--start-delay"))
                                                         : 1'000'000'000ull;
    const uint64_t start =
        master.start_real_time(nodes, std::chrono::milliseconds(delay / 1'000'000), std::chrono::seconds(30));
    std::printf("all %zu nodes ready; start at %llu ns\n", nodes.size(), static_cast<unsigned long long>(start));
    std::fflush(stdout);
    cpm::cli::stop_on_signals();
    const uint64_t end = flags.count("--duration") ? start + parse_duration("--duration", flags.at("--duration"))
                                                   : UINT64_MAX;
    while (!cpm::cli::stop_requested() && cpm::get_time_ns() < end) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    master.stop_all();
    std::printf("stopped all timers\n");
    return 0;
}

int topic_echo(const std::vector<std::string>& args)
{
    const auto parsed = parse_args(args, {{"--json", false}, {"--count", true}, {"--timeout", true}}, "cpm topic echo");
    const std::string topic = only_positional(parsed, "cpm topic echo", "topic");
    if (topic != "log") {
        throw UsageError("cpm topic echo: topic '" + topic + "' is not supported yet (supported: log)");
    }
    const auto& flags = parsed.flags;
    const bool json = flags.count("--json") > 0;
    uint64_t count = UINT64_MAX;
    if (flags.count("--count")) {
        count = static_cast<uint64_t>(cpm::cli::parse_integer("--count", flags.at("--count"), 1, INT64_MAX));
    }
    const uint64_t timeout_ns = flags.count("--timeout") ? parse_duration("--timeout", flags.at("--timeout")) : 0;

    cpm::Participant participant;
    cpm::ReaderOptions options;
    options.reliable = true;
    options.transient_local = true;
    options.history_depth = 100;
    cpm::ReaderAbstract<Log> reader(participant, "log", options);
    cpm::cli::stop_on_signals();
    static const char* levels[] = {"?", "error", "warn", "info", "debug"};
    if (!json) std::printf("%-20s %-16s %-6s %s\n", "time_ns", "node", "level", "message");
    uint64_t printed = 0;
    auto last = std::chrono::steady_clock::now();
    while (!cpm::cli::stop_requested() && printed < count) {
        if (timeout_ns > 0 && uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                           std::chrono::steady_clock::now() - last).count()) > timeout_ns) {
            std::fprintf(stderr, "cpm topic echo: no message for %s\n", flags.at("--timeout").c_str());
            return 1;
        }
        if (!reader.wait_for_data(std::chrono::milliseconds(100))) continue;
        last = std::chrono::steady_clock::now();
        for (const auto& l : reader.take()) {
            const char* level = l.log_level() <= 4 ? levels[l.log_level()] : "?";
            if (json) {
                nlohmann::json line{{"topic", "log"},
                                    {"data", {{"id", l.id()}, {"content", l.content()},
                                              {"stamp", {{"nanoseconds", l.stamp().nanoseconds()}}},
                                              {"log_level", l.log_level()}}}};
                std::printf("%s\n", line.dump().c_str());
            } else {
                std::printf("%-20llu %-16s %-6s %s\n", static_cast<unsigned long long>(l.stamp().nanoseconds()),
                            l.id().c_str(), level, l.content().c_str());
            }
            std::fflush(stdout);
            if (++printed >= count) break;
        }
    }
    return 0;
}

int fsm_check(const std::vector<std::string>& args)
{
    const std::string file = only_positional(parse_args(args, {}, "cpm fsm check"), "cpm fsm check", "machine file");
    auto result = cpm::fsm::load_file(file);
    for (const auto& e : result.errors) std::printf("error: %s\n", e.text().c_str());
    for (const auto& w : result.warnings) std::printf("warning: %s\n", w.text().c_str());
    if (!result.ok()) {
        std::printf("%s: %zu error(s), %zu warning(s)\n", file.c_str(), result.errors.size(), result.warnings.size());
        return 1;
    }
    std::printf("%s: ok (%zu states, %zu transitions, %zu warning(s))\n", file.c_str(), result.machine->states().size(),
                result.machine->transitions().size(), result.warnings.size());
    return 0;
}

int fsm_convert(const std::vector<std::string>& args)
{
    const std::string file = only_positional(parse_args(args, {}, "cpm fsm convert"), "cpm fsm convert", ".uxf file");
    auto checked = cpm::fsm::load_file(file);
    for (const auto& e : checked.errors) std::fprintf(stderr, "error: %s\n", e.text().c_str());
    for (const auto& w : checked.warnings) std::fprintf(stderr, "warning: %s\n", w.text().c_str());
    if (!checked.ok()) return 1;
    std::printf("%s\n", checked.json.c_str());
    return 0;
}

int fsm_render(const std::vector<std::string>& args)
{
    std::vector<std::string> spelled = args;
    for (auto& a : spelled) {
        if (a == "-o") a = "--output";  // the short form, as in dot and cc
    }
    const auto parsed = parse_args(spelled, {{"--output", true}}, "cpm fsm render");
    const std::string file = only_positional(parsed, "cpm fsm render", "machine file");
    const std::string out = parsed.get("--output");
    if (out.empty()) throw UsageError("cpm fsm render: -o OUT.svg|OUT.png|OUT.dot is required");
    const std::string format = out.substr(out.rfind('.') == std::string::npos ? out.size() : out.rfind('.') + 1);
    if (format != "svg" && format != "png" && format != "dot") {
        throw UsageError("cpm fsm render: -o " + out + ": the name must end in .svg, .png or .dot");
    }
    auto result = cpm::fsm::machine_to_dot(file);
    for (const auto& e : result.errors) std::fprintf(stderr, "error: %s\n", e.text().c_str());
    if (!result.errors.empty()) return 1;
    if (format == "dot") {
        std::ofstream(out) << result.dot;
    } else {
        const std::string command = "dot -T" + format + " -o '" + out + "'";
        FILE* pipe = popen(command.c_str(), "w");
        if (!pipe) throw std::runtime_error("cannot run Graphviz's dot (install the Debian package graphviz)");
        std::fputs(result.dot.c_str(), pipe);
        const int status = pclose(pipe);
        if (status != 0) throw std::runtime_error("Graphviz's dot failed (exit " + std::to_string(WEXITSTATUS(status)) +
                                                  "; is the Debian package graphviz installed?)");
    }
    std::printf("%s: wrote %s\n", file.c_str(), out.c_str());
    return 0;
}

int param_serve(const std::vector<std::string>& args)
{
    const std::string file = only_positional(parse_args(args, {}, "cpm param serve"), "cpm param serve",
                                             "parameter file");
    cpm::Participant participant;
    cpm::ParameterServer server(participant);
    const size_t n = server.load_file(file);
    std::printf("serving %zu parameters from %s\n", n, file.c_str());
    std::fflush(stdout);
    cpm::cli::stop_on_signals();
    while (!cpm::cli::stop_requested()) std::this_thread::sleep_for(std::chrono::milliseconds(50));
    return 0;
}

}  // namespace

int main(int argc, char** argv)
{
    std::vector<std::string> args(argv + 1, argv + argc);
    const bool help = cpm::cli::wants_help(args);
    try {
        if (args.empty() || args[0] == "help" || (help && args.size() == 1)) {
            std::fputs(kTopHelp, stdout);
            return args.empty() ? kUsageError : 0;
        }
        struct Command
        {
            const char* group;
            const char* verb;
            const char* help;
            int (*run)(const std::vector<std::string>&);
        };
        static const Command commands[] = {{"lab", "clock", kClockHelp, lab_clock},
                                           {"topic", "echo", kEchoHelp, topic_echo},
                                           {"param", "serve", kParamHelp, param_serve},
                                           {"vehicle", "sim", kVehicleSimHelp, vehicle_sim},
                                           {"fsm", "check", kFsmCheckHelp, fsm_check},
                                           {"fsm", "convert", kFsmConvertHelp, fsm_convert},
                                           {"fsm", "render", kFsmRenderHelp, fsm_render}};
        if (args[0] == "dump" || args[0] == "history") {
            if (help) {
                std::fputs(args[0] == "dump" ? cpm::tools::kDumpHelp : cpm::tools::kHistoryHelp, stdout);
                return 0;
            }
            cpm::init(argc, argv);
            if (args[0] == "dump") return cpm::tools::dump_command(std::vector<std::string>(args.begin() + 1, args.end()));
            if (args.size() < 2) throw UsageError("cpm history: which query? (see cpm history --help)");
            return cpm::tools::history_command(args[1], std::vector<std::string>(args.begin() + 2, args.end()));
        }
        for (const auto& c : commands) {
            if (args.size() < 2 || args[0] != c.group || args[1] != c.verb) continue;
            if (help) {
                std::fputs(c.help, stdout);
                return 0;
            }
            cpm::init(argc, argv);
            return c.run(std::vector<std::string>(args.begin() + 2, args.end()));
        }
        throw UsageError("unknown command '" + args[0] + (args.size() > 1 ? " " + args[1] : "") + "' (see cpm --help)");
    } catch (const UsageError& e) {
        std::fprintf(stderr, "cpm: %s\n", e.what());
        return kUsageError;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "cpm: %s\n", e.what());
        return 1;
    }
}
