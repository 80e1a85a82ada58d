#include <cpm/lab/Run.hpp>

#include <cpm/ChildProcess.hpp>
#include <cpm/HistoryClient.hpp>
#include <cpm/Participant.hpp>
#include <cpm/TimeMaster.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/stamp_message.hpp>
#include <cpm/topics.hpp>

#include <StopRequest.h>
#include <cpm_topic_types.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <ctime>
#include <deque>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>
#include <unistd.h>

namespace cpm::lab {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

std::string utc_now_compact()
{
    const std::time_t t = std::time(nullptr);
    std::tm tm{};
    ::gmtime_r(&t, &tm);
    char b[32];
    std::strftime(b, sizeof b, "%Y%m%dT%H%M%SZ", &tm);
    return b;
}

/// The last `n` lines of a file.
std::string tail(const std::string& path, size_t n)
{
    std::ifstream in(path);
    std::deque<std::string> lines;
    for (std::string line; std::getline(in, line);) {
        lines.push_back(line);
        if (lines.size() > n) lines.pop_front();
    }
    std::string out;
    for (const auto& l : lines) out += "    " + l + "\n";
    return out;
}

/// The last line of a file that is a JSON object (a cpm program's statistics at its end).
nlohmann::json last_json(const std::string& path)
{
    std::ifstream in(path);
    nlohmann::json found;
    for (std::string line; std::getline(in, line);) {
        if (line.empty() || line[0] != '{') continue;
        try {
            found = nlohmann::json::parse(line);
        } catch (const std::exception&) {
        }
    }
    return found;
}

struct Node
{
    ProcessPlan plan;
    std::string log;
    std::optional<ChildProcess> child;
    int restarts = 0;
    std::optional<ExitStatus> end;
    bool died = false;  ///< ended badly while the run went on
};

void start(Node& n, int domain, bool append)
{
    if (append) std::ofstream(n.log, std::ios::app) << "\n--- restarted by cpm lab run ---\n";
    n.child.emplace(ProcessOptions{.argv = n.plan.argv,
                                   .env = {"CPM_DOMAIN_ID=" + std::to_string(domain)},
                                   .stdout_path = n.log,
                                   .stderr_path = n.log,
                                   .append_output = append,
                                   .own_process_group = true,
                                   .die_with_parent = true});
    n.end.reset();
}

}  // namespace

RunResult run_lab(const Scenario& s, const RunOptions& o)
{
    RunSettings settings;
    settings.bin_dir = o.bin_dir.empty() ? cpm::executable_dir() : o.bin_dir;
    settings.domain = o.domain.value_or(s.domain.value_or(ParticipantOptions::from_init().domain_id));
    settings.time = o.time.value_or(s.time);
    settings.duration_ns = o.duration_ns.value_or(s.duration_ns);
    const fs::path dir = fs::absolute(o.out_dir.empty() ? fs::path("runs") / (s.name + "-" + utc_now_compact()) : fs::path(o.out_dir));
    std::error_code ec;
    if (fs::exists(dir, ec) && !fs::is_empty(dir, ec)) throw std::runtime_error("the run's folder " + dir.string() + " exists and is not empty");
    fs::create_directories(dir, ec);
    if (ec) throw std::runtime_error("cannot make the run's folder " + dir.string() + ": " + ec.message());
    settings.run_dir = dir.string();
    const auto plan = plan_run(s, settings);  // names a missing program before anything starts
    fs::copy_file(s.file, dir / "scenario.yaml", fs::copy_options::overwrite_existing, ec);

    RunResult result;
    result.dir = dir.string();
    auto say = [&](const std::string& line) {
        if (o.progress) std::fprintf(o.progress, "%s\n", line.c_str());
    };
    const bool tty = o.progress && ::isatty(::fileno(o.progress));
    const auto t0 = Clock::now();

    ParticipantOptions po = ParticipantOptions::from_init();
    po.domain_id = settings.domain;
    po.name = "cpm_lab_run";
    po.shared_memory = false;  // short-lived beside many processes: UDP loopback (see cpm history)
    Participant participant(po);
    Writer<StopRequest> stops(participant, topics::stop_request.name, topics::stop_request.writer);
    HistoryClient history(participant, std::chrono::milliseconds(2000));

    std::vector<Node> nodes;
    for (const auto& p : plan) nodes.push_back({p, (dir / (p.name + ".log")).string()});

    // The history first, so that the recording holds the run from its first sample.
    start(nodes[0], settings.domain, false);
    bool history_up = false;
    const auto history_deadline = Clock::now() + std::chrono::seconds(15);
    while (!history_up && Clock::now() < history_deadline && !o.stop() && nodes[0].child->running()) {
        try {
            history_up = history.request(HistoryClient::make(history::Kind::list, "", "")).status() == "ok";
        } catch (const std::exception&) {
        }
    }
    if (!history_up) {
        result.error = "the history service did not answer within 15 s; the end of its log:\n" + tail(nodes[0].log, 10);
    }
    for (size_t i = 1; i < nodes.size() && result.error.empty(); ++i) start(nodes[i], settings.domain, false);
    say("cpm lab run: " + s.name + ": " + std::to_string(nodes.size()) + " processes on domain " + std::to_string(settings.domain) +
        ", logs and recording in " + dir.string());

    // The clock: simulated time driven through the timers' ticks on a thread of its own; real
    // time started together a second ahead when a node waits for the start.
    std::vector<std::string> timers;
    for (const auto& n : nodes) {
        std::stringstream list(n.plan.timer);
        for (std::string t; std::getline(list, t, ',');) timers.push_back(t);
    }
    TimeMaster master(participant);
    std::atomic<bool> clock_done{false};
    std::atomic<uint64_t> simulated_until{0};
    std::string clock_error;
    std::thread clock;
    uint64_t real_start = cpm::get_time_ns();
    if (result.error.empty()) {
        if (settings.time == TimeMode::simulated) {
            clock = std::thread([&] {
                try {
                    master.run_simulated(timers, settings.duration_ns);
                    simulated_until = settings.duration_ns;
                } catch (const std::exception& e) {
                    clock_error = e.what();
                }
                clock_done = true;
            });
        } else if (s.routing.enabled) {
            try {
                real_start = master.start_real_time({"central_routing"}, std::chrono::milliseconds(1000), std::chrono::seconds(30));
            } catch (const std::exception& e) {
                result.error = std::string("the lab clock could not start: ") + e.what();
            }
        }
    }

    // Supervise: a node that dies is restarted when its scenario says so, else the run ends.
    auto last_progress = Clock::now();
    while (result.error.empty()) {
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
        if (o.stop()) {
            result.interrupted = true;
            break;
        }
        for (auto& n : nodes) {
            if (!n.child || n.end || n.child->running()) continue;
            n.end = n.child->ended();
            // Exit code 0 is a node that is done: an fsm_node whose machine reached a stop state,
            // the nodes the simulated clock stopped at its end.
            if (n.end && n.end->ok()) continue;
            if (n.plan.restart) {
                ++n.restarts;
                say("cpm lab run: " + n.plan.name + " " + n.end->describe() + "; restarting it (restart: true)");
                start(n, settings.domain, true);
                continue;
            }
            n.died = true;
            result.error = n.plan.name + " " + n.end->describe() + " during the run; the end of its log (" + n.log + "):\n" + tail(n.log, 10);
        }
        if (!result.error.empty()) break;
        const bool simulated = settings.time == TimeMode::simulated;
        const uint64_t lab_now = simulated ? 0 : cpm::get_time_ns() - std::min(cpm::get_time_ns(), real_start);
        if (simulated && clock_done) {
            if (!clock_error.empty()) result.error = "the simulated clock stopped: " + clock_error;
            break;
        }
        if (!simulated && lab_now >= settings.duration_ns) break;
        if (Clock::now() - last_progress >= std::chrono::seconds(tty ? 1 : 10) && o.progress) {
            last_progress = Clock::now();
            const double real = std::chrono::duration<double>(Clock::now() - t0).count();
            char line[200];
            if (simulated) std::snprintf(line, sizeof line, "%.0f s real, simulated clock running to %.1f s, %zu car(s)", real, double(settings.duration_ns) * 1e-9, s.vehicles.size());
            else std::snprintf(line, sizeof line, "lab time %.1f / %.1f s, %zu car(s)", double(lab_now) * 1e-9, double(settings.duration_ns) * 1e-9, s.vehicles.size());
            std::fprintf(o.progress, tty ? "\r%s   " : "%s\n", line);
            std::fflush(o.progress);
        }
    }
    if (tty) std::fprintf(o.progress, "\n");
    result.lab_time_ns = settings.time == TimeMode::simulated ? simulated_until.load()
                                                              : std::min(settings.duration_ns, cpm::get_time_ns() - std::min(cpm::get_time_ns(), real_start));

    // The end, in order: every car told to stop, the timers stopped, then the processes that
    // command the cars, the cars, and the history last (it closes the recording).
    StopRequest all;
    all.vehicle_id(0);
    cpm::stamp_message(all, cpm::get_time_ns(), 0);
    (void)stops.write(all);
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    master.stop_all();
    std::vector<Node*> order;
    for (auto& n : nodes) order.push_back(&n);
    std::stable_sort(order.begin(), order.end(), [](const Node* a, const Node* b) { return a->plan.stop_order < b->plan.stop_order; });
    for (Node* n : order) {
        if (!n->child || n->end) continue;
        n->child->signal(SIGINT);
        n->end = n->child->wait(std::chrono::seconds(n->plan.name == "cpm_history" ? 30 : 5));
        if (!n->end) n->end = n->child->stop(std::chrono::seconds(2));
    }
    if (clock.joinable()) clock.join();
    result.real_seconds = std::chrono::duration<double>(Clock::now() - t0).count();

    nlohmann::json processes = nlohmann::json::array();
    for (auto& n : nodes) {
        ProcessEnd e{n.plan.name, n.end ? n.end->describe() : "never started"};
        // Stopped by the run: SIGINT's exit code 0, or ended by SIGINT/SIGTERM, is a clean end.
        const bool clean = n.end && (n.end->ok() || n.end->signal == SIGINT || n.end->signal == SIGTERM);
        e.failed = n.died || (n.child && !clean);
        e.restarts = n.restarts;
        if (e.failed) e.last_lines = tail(n.log, 10);
        processes.push_back({{"name", e.name}, {"argv", n.plan.argv}, {"end", e.how}, {"failed", e.failed}, {"restarts", e.restarts},
                             {"log", fs::path(n.log).filename().string()}});
        result.processes.push_back(e);
    }
    result.ok = result.error.empty() && !result.interrupted &&
                std::none_of(result.processes.begin(), result.processes.end(), [](const ProcessEnd& e) { return e.failed; });
    const auto recorded = last_json(nodes[0].log);
    nlohmann::json summary{{"name", s.name},
                           {"scenario", fs::absolute(s.file).string()},
                           {"time", settings.time == TimeMode::simulated ? "simulated" : "real"},
                           {"domain", settings.domain},
                           {"duration_s", double(settings.duration_ns) * 1e-9},
                           {"lab_time_s", double(result.lab_time_ns) * 1e-9},
                           {"real_s", result.real_seconds},
                           {"ok", result.ok},
                           {"interrupted", result.interrupted},
                           {"error", result.error},
                           {"vehicles", s.vehicles.size()},
                           {"world", s.world},
                           {"lanes", s.lanes},
                           {"processes", processes},
                           {"recording", recorded.contains("recording") ? recorded["recording"] : nlohmann::json()}};
    std::ofstream(dir / "summary.json") << summary.dump(2) << "\n";
    return result;
}

}  // namespace cpm::lab
