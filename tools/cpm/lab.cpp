// cpm lab …: the lab's clock, and lab scenarios checked.
#include "Command.hpp"

#include <cpm/Bookmark.hpp>
#include <cpm/ChildProcess.hpp>
#include <cpm/CommandLine.hpp>
#include <cpm/Participant.hpp>
#include <cpm/lab/Report.hpp>
#include <cpm/lab/Run.hpp>
#include <cpm/lab/Scenario.hpp>
#include <cpm/TimeMaster.hpp>
#include <cpm/get_time_ns.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <thread>

namespace cpm::tools {
namespace {

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

int lab_clock(const std::vector<std::string>& args)
{
    const auto parsed = parse_flags(
        args, {{"--nodes", true}, {"--simulated", false}, {"--until", true}, {"--start-delay", true}, {"--duration", true}},
        "cpm lab clock");
    const auto& flags = parsed.flags;
    if (!flags.count("--nodes")) throw UsageError("cpm lab clock: --nodes is required (the timers' node ids)");
    const auto nodes = split_list("--nodes", flags.at("--nodes"));
    // Every flag is checked before anything waits.
    if (flags.count("--simulated") && !flags.count("--until")) throw UsageError("cpm lab clock --simulated: --until is required");
    const uint64_t until = flags.count("--until") ? parse_duration("--until", flags.at("--until")) : 0;
    const uint64_t delay = flags.count("--start-delay") ? parse_duration("--start-delay", flags.at("--start-delay"))
                                                         : 1'000'000'000ull;
    const uint64_t duration = flags.count("--duration") ? parse_duration("--duration", flags.at("--duration")) : 0;
    cpm::Participant participant;
    cpm::TimeMaster master(participant);

    if (flags.count("--simulated")) {
        const auto t0 = std::chrono::steady_clock::now();
        const uint64_t steps = master.run_simulated(nodes, until);
        const double real = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        std::printf("simulated %.3f s in %.3f real s (%llu steps, %.1fx real time); stopped all timers\n",
                    double(until) * 1e-9, real, static_cast<unsigned long long>(steps),
                    real > 0 ? double(until) * 1e-9 / real : 0.0);
        return 0;
    }
    const uint64_t start =
        master.start_real_time(nodes, std::chrono::milliseconds(delay / 1'000'000), std::chrono::seconds(30));
    std::printf("all %zu nodes ready; start at %llu ns\n", nodes.size(), static_cast<unsigned long long>(start));
    std::fflush(stdout);
    cpm::cli::stop_on_signals();
    const uint64_t end = flags.count("--duration") ? start + duration : UINT64_MAX;
    while (!cpm::cli::stop_requested() && cpm::get_time_ns() < end) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    master.stop_all();
    std::printf("stopped all timers\n");
    return 0;
}

const char* kLabCheckHelp =
    "usage: cpm lab check FILE [--dds_domain N]\n"
    "\n"
    "Reads a lab scenario (scenarios/labs/*.yaml: name, domain, time, duration, world, lanes,\n"
    "vehicles with id, start, camera, fsm and restart, routing, qos, record, monitor) and checks\n"
    "it: every error at once, each with its line and YAML path (an unknown key, a file that does\n"
    "not exist, a vehicle id given twice, a bad duration, a combination a run cannot do), exit 1.\n"
    "When it is right, prints the processes a run of it starts, with their command lines.\n";

int lab_check(const std::vector<std::string>& args)
{
    const std::string command = "cpm lab check";
    const std::string file = only_positional(parse_args(args, {}, command), command, "scenario file");
    cpm::lab::Scenario s;
    try {
        s = cpm::lab::load_scenario(file);
    } catch (const cpm::lab::ScenarioError& e) {
        std::fprintf(stderr, "%s: %zu error(s):\n%s\n", command.c_str(), e.errors().size(), e.what());
        return 1;
    }
    cpm::lab::RunSettings settings;
    settings.bin_dir = cpm::executable_dir();
    settings.run_dir = "runs/" + s.name + "-<UTC time>";
    settings.domain = s.domain.value_or(cpm::ParticipantOptions::from_init().domain_id);
    settings.duration_ns = s.duration_ns;
    settings.time = s.time;
    std::vector<cpm::lab::ProcessPlan> plan;
    try {
        plan = cpm::lab::plan_run(s, settings);
    } catch (const cpm::lab::ScenarioError& e) {
        std::fprintf(stderr, "%s: %s\n", command.c_str(), e.what());
        return 1;
    }
    std::printf("%s: ok: %s, %zu car(s), %s time, %.1f s on domain %d; a run starts %zu processes:\n", file.c_str(), s.name.c_str(),
                s.vehicles.size(), s.time == cpm::lab::TimeMode::simulated ? "simulated" : "real", double(s.duration_ns) * 1e-9,
                settings.domain, plan.size());
    std::printf("  timeouts: a run waits %g s for its processes to start, %g s for each step of simulated time\n",
                double(s.timeouts.start_ns) * 1e-9, double(s.timeouts.step_ns) * 1e-9);
    auto print = [](const cpm::lab::ProcessPlan& p) {
        std::string line;
        for (const auto& a : p.argv) line += (line.empty() ? "" : " ") + a;
        std::printf("  %-16s %s%s\n", p.name.c_str(), line.c_str(), p.restart ? "   (restarted when it dies)" : "");
    };
    if (s.hosts.empty()) {
        for (const auto& p : plan) print(p);
        return 0;
    }
    for (const auto& h : s.hosts) {  // the plan per host, as each host will run it
        std::printf("on %s (%s%s):\n", h.name.c_str(), h.address.c_str(), h.ssh.empty() ? ", this host" : (", ssh " + h.ssh + ", cpm in " + h.cpm).c_str());
        for (const auto& p : plan) {
            if (p.host == h.name) print(p);
        }
    }
    return 0;
}

const char* kRunHelp =
    "usage: cpm lab run FILE [--out DIR] [--duration T] [--time simulated|real] [--monitor PORT|off]\n"
    "                   [--dds_domain N] [--dds_shared_memory on|off]\n"
    "\n"
    "Runs a lab scenario (see cpm lab check): checks it (every error at once, nothing started)\n"
    "and claims its domain (refused when another run on this host has it or anybody is on it),\n"
    "then starts cpm_history recording into the run's folder, the parameter server (parameters:),\n"
    "cpm monitor (monitor: PORT, or --monitor PORT; its address is printed; --monitor off: none),\n"
    "the cars (cpm vehicle sim), their cameras' aruco_nodes, central_routing and the fsm_nodes,\n"
    "every one with the scenario's qos: overrides, and drives the lab clock: in real time for\n"
    "--duration (routing starts together a second ahead), in simulated time as fast as the\n"
    "slowest node computes. The progress line (redrawn on a terminal, else every 10 s): lab time,\n"
    "cars, deadlines the nodes' timers missed, samples recorded. A process that dies ends the run\n"
    "with the end of its log (or is\n"
    "restarted, with restart: true). At the end, or on Ctrl-C: a StopRequest to every car, the\n"
    "timers stopped, the processes stopped in order, the history last (the recording closed).\n"
    "The run's folder (--out, default runs/<name>-<UTC time>) holds <process>.log for each\n"
    "process, recording.db (ask it with cpm history --file, replay it with cpm play),\n"
    "scenario.yaml, summary.json and the report (report.html with its plots, see cpm lab report).\n"
    "Exit 0 when every process ran its time and the report was drawn; 1 otherwise.\n"
    "--dds_domain (or the scenario's domain: key, else CPM_DOMAIN_ID) picks the domain.\n"
    "In simulated time the run's processes talk over UDP loopback only (Fast DDS would send\n"
    "every sample over shared memory and UDP both, and each step waits for them);\n"
    "--dds_shared_memory on (or CPM_SHARED_MEMORY=on) keeps shared memory.\n";

int lab_run(const std::vector<std::string>& args)
{
    const std::string command = "cpm lab run";
    const auto parsed = parse_args(args, {{"--out", true}, {"--duration", true}, {"--time", true}, {"--monitor", true}}, command);
    const std::string file = only_positional(parsed, command, "scenario file");
    cpm::lab::RunOptions options;
    if (parsed.has("--duration")) {
        options.duration_ns = parse_duration("--duration", parsed.get("--duration"));
        if (*options.duration_ns == 0) throw UsageError(command + ": --duration must be longer than 0");
    }
    if (parsed.has("--time")) {
        const std::string t = parsed.get("--time");
        if (t != "real" && t != "simulated") throw UsageError(command + ": --time '" + t + "': expected real or simulated");
        options.time = t == "simulated" ? cpm::lab::TimeMode::simulated : cpm::lab::TimeMode::real;
    }
    options.out_dir = parsed.get("--out");
    if (std::find(args.begin(), args.end(), "--dds_domain") != args.end()) options.domain = cpm::ParticipantOptions::from_init().domain_id;
    cpm::lab::Scenario s;
    try {
        s = cpm::lab::load_scenario(file);
    } catch (const cpm::lab::ScenarioError& e) {
        std::fprintf(stderr, "%s: %zu error(s), nothing started:\n%s\n", command.c_str(), e.errors().size(), e.what());
        return 1;
    }
    if (parsed.has("--monitor")) {
        const std::string m = parsed.get("--monitor");
        if (m == "off") {
            s.monitor_port.reset();
        } else {
            s.monitor_port = int(cpm::cli::parse_integer(command + ": --monitor (a port, or off)", m, 1, 65535));
        }
    }
    cpm::cli::stop_on_signals();
    options.progress = stderr;
    options.stop = [] { return cpm::cli::stop_requested(); };
    cpm::lab::RunResult r;
    try {
        r = cpm::lab::run_lab(s, options);
    } catch (const std::runtime_error& e) {  // a missing program, a domain in use, a folder that cannot be made
        std::fprintf(stderr, "%s: nothing started:\n%s\n", command.c_str(), e.what());
        return 1;
    }
    int status = r.ok ? 0 : 1;
    std::string report;
    try {
        report = cpm::lab::make_report(r.dir).html;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "%s: the report could not be drawn: %s\n", command.c_str(), e.what());
        status = 1;
    }
    for (const auto& p : r.processes) {
        // The process the run ended for is told below, with the end of its log.
        if (p.failed && r.error.rfind(p.name + " ", 0) != 0) std::fprintf(stderr, "%s: %s %s%s\n%s", command.c_str(), p.name.c_str(), p.how.c_str(),
                                   p.restarts ? (" (restarted " + std::to_string(p.restarts) + " times)").c_str() : "", p.last_lines.c_str());
    }
    if (!r.error.empty()) std::fprintf(stderr, "%s: the run ended early: %s\n", command.c_str(), r.error.c_str());
    if (const std::string loss = cpm::lab::recording_loss(r.recording_lost_by_topic); !loss.empty())
        std::fprintf(stderr, "%s: the recording misses what it should hold: %s\n", command.c_str(), loss.c_str());
    char speed[96] = "";
    if (r.clock_seconds > 0) {
        std::snprintf(speed, sizeof speed, " (the simulated clock: %.1f s, %.1fx real time)", r.clock_seconds,
                      double(r.lab_time_ns) * 1e-9 / r.clock_seconds);
    }
    std::printf("%s %s: %.1f s of lab time in %.1f s%s; %s (summary.json, recording.db, a .log per process)\n", s.name.c_str(),
                r.ok ? "ran" : r.interrupted ? "was stopped" : "FAILED", double(r.lab_time_ns) * 1e-9, r.real_seconds, speed, r.dir.c_str());
    if (!report.empty()) std::printf("report: %s\n", report.c_str());
    return status;
}

const char* kReportHelp =
    "usage: cpm lab report DIR\n"
    "\n"
    "Draws a run's report again from its folder (recording.db, summary.json): report.html with\n"
    "its plots (made with gnuplot) in DIR/plots: each car's path on the map, speed, steering, the\n"
    "state machines' states, clearance to walls, the smallest distance between cars, per-topic\n"
    "rates and delays, the run's warnings and errors; the same figures go into summary.json.\n";

int lab_report(const std::vector<std::string>& args)
{
    const std::string command = "cpm lab report";
    const std::string dir = only_positional(parse_args(args, {}, command), command, "run folder");
    try {
        const auto r = cpm::lab::make_report(dir);
        std::printf("%s (%zu plots)\n", r.html.c_str(), r.images.size());
    } catch (const std::exception& e) {
        std::fprintf(stderr, "%s: %s\n", command.c_str(), e.what());
        return 1;
    }
    return 0;
}

const char* kMarkHelp =
    "usage: cpm lab mark TEXT [--source NAME] [--dds_domain N]\n"
    "\n"
    "Marks this moment of the lab with TEXT (at most 256 bytes, one line): a Bookmark on the\n"
    "bookmark topic, recorded by the history with everything else, listed by cpm history marks\n"
    "(live or --file), drawn in the report's plots and exported as MCAP metadata (cpm.bookmark).\n"
    "--source: who marks it (default: cpm lab mark). Exit code 1 when no history records it.\n";

int lab_mark(const std::vector<std::string>& args)
{
    const std::string command = "cpm lab mark";
    const auto parsed = parse_args(args, {{"--source", true}}, command);
    const std::string text = only_positional(parsed, command, "text");
    const std::string source = parsed.get("--source", "cpm lab mark");
    if (const std::string problem = cpm::bookmark_problem(text, source); !problem.empty()) throw UsageError(command + ": " + problem);
    cpm::Participant participant;
    try {
        const auto m = cpm::mark(participant, text, source);
        std::printf("marked %s: %s\n", cpm::cli::format_time(m.stamp_ns, 3).c_str(), text.c_str());
    } catch (const cpm::Error& e) {
        std::fprintf(stderr, "%s: %s\n", command.c_str(), e.what());
        return 1;
    }
    return 0;
}

}  // namespace

std::vector<Command> lab_commands()
{
    return {{.group = "lab", .verb = "clock", .summary = "drive the lab's timers: a synchronised real-time start and stop, or a simulated clock", .help = kClockHelp, .run = lab_clock},
            {.group = "lab", .verb = "check", .summary = "check a lab scenario file and show the processes a run of it starts", .help = kLabCheckHelp, .run = lab_check},
            {.group = "lab", .verb = "run", .summary = "run a lab scenario: every process started, supervised, recorded and stopped in order", .help = kRunHelp, .run = lab_run},
            {.group = "lab", .verb = "mark", .summary = "mark this moment of the lab with a text (recorded, listed by cpm history marks, in the report)", .help = kMarkHelp, .run = lab_mark},
            {.group = "lab", .verb = "report", .summary = "draw a run's report (report.html with plots, summary.json) from its folder", .help = kReportHelp, .run = lab_report}};
}

}  // namespace cpm::tools
