// cpm monitor's cost, measured with the monitor as its own process (`cpm monitor`, as a lab runs
// it) and real watchers (HTTP clients reading /api/stream):
//   - latency from a VehicleState's create_stamp to the snapshot holding it arriving at a watcher
//     on this host, p50/p99, with 1 and 10 watchers (target p99 <= 50 ms); beside it, the same
//     samples' latency to a plain cpm reader in this process (the DDS floor, same run);
//   - the monitor's CPU with 20 cars at 50 Hz (VehicleState, VehicleObservation, RangeSensors),
//     from /proc/PID/stat over the measured window (target <= 10 % of one core);
//   - snapshots per second each watcher got.
//
//   bench_monitor [--seconds 10] [--domain 212]
#include "bench_common.hpp"

#include <cpm/AsyncReader.hpp>
#include <cpm/ChildProcess.hpp>
#include <cpm/CommandLine.hpp>
#include <cpm/Participant.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/stamp_message.hpp>
#include <cpm/topics.hpp>

#include <RangeSensors.h>
#include <VehicleObservation.h>
#include <VehicleState.h>

#include <httplib.h>
#include <nlohmann/json.hpp>

#include <atomic>
#include <cstdio>
#include <fstream>
#include <map>
#include <mutex>
#include <regex>
#include <thread>
#include <unistd.h>

namespace t = cpm::topics;
using namespace std::chrono_literals;

namespace {

/// CPU seconds (user + system) a process has used so far.
double cpu_seconds(int pid)
{
    std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
    std::string text((std::istreambuf_iterator<char>(stat)), std::istreambuf_iterator<char>());
    const auto close = text.rfind(')');
    std::istringstream rest(text.substr(close + 2));
    std::string field;
    unsigned long long utime = 0, stime = 0;
    for (int i = 3; i <= 15 && rest >> field; ++i) {
        if (i == 14) utime = std::stoull(field);
        if (i == 15) stime = std::stoull(field);
    }
    return double(utime + stime) / double(::sysconf(_SC_CLK_TCK));
}

struct Case
{
    int cars, watchers;
};

struct Result
{
    bench::Stats monitor, dds;
    double cpu_percent = 0, updates_per_watcher = 0;
};

Result run_case(const Case& c, int port, int monitor_pid, cpm::Participant& participant, double seconds)
{
    cpm::Writer<VehicleState> states(participant, t::vehicle_state.name, t::vehicle_state.writer);
    cpm::Writer<VehicleObservation> seen(participant, t::vehicle_observation.name, t::vehicle_observation.writer);
    cpm::Writer<RangeSensors> ranges(participant, t::range_sensors.name, t::range_sensors.writer);
    std::mutex mutex;
    std::vector<double> monitor_us, dds_us;
    std::atomic<bool> measuring{false}, done{false};
    std::atomic<long> updates{0};
    cpm::AsyncReader<VehicleState> floor(
        [&](std::vector<VehicleState>& batch) {
            const uint64_t now = cpm::get_time_ns();
            if (!measuring) return;
            std::lock_guard lock(mutex);
            for (const auto& s : batch) dds_us.push_back(double(now - s.header().create_stamp().nanoseconds()) * 1e-3);
        },
        participant, t::vehicle_state.name, t::vehicle_state.reader);
    std::vector<std::thread> watchers;
    for (int w = 0; w < c.watchers; ++w) {
        watchers.emplace_back([&] {
            httplib::Client http("127.0.0.1", port);
            std::string buffer;
            std::map<int, uint64_t> newest;  // per car, the newest state stamp this watcher had
            http.Get("/api/stream", [&](const char* data, size_t n) {
                const uint64_t now = cpm::get_time_ns();
                buffer.append(data, n);
                for (size_t end; (end = buffer.find("\n\n")) != std::string::npos; buffer.erase(0, end + 2)) {
                    if (buffer.rfind("data: ", 0) != 0) continue;  // a keep-alive
                    const auto snap = nlohmann::json::parse(buffer.substr(6, end - 6), nullptr, false);
                    if (snap.is_discarded() || !measuring) continue;
                    ++updates;
                    std::lock_guard lock(mutex);
                    for (const auto& v : snap["vehicles"]) {
                        if (!v.contains("state_stamp_ns")) continue;
                        const uint64_t stamp = v["state_stamp_ns"];
                        uint64_t& last = newest[v["id"].get<int>()];
                        if (stamp > last && last != 0) monitor_us.push_back(double(now - stamp) * 1e-3);
                        last = stamp;
                    }
                }
                return !done.load();
            });
        });
    }
    auto publish = [&] {
        const uint64_t now = cpm::get_time_ns();
        for (int id = 1; id <= c.cars; ++id) {
            VehicleState s;
            s.vehicle_id(uint8_t(id));
            s.pose().x(0.1 * id);
            s.speed(0.5);
            cpm::stamp_message(s, now, 0);
            (void)states.write(s);
            VehicleObservation o;
            o.vehicle_id(uint8_t(id));
            o.pose().x(0.1 * id);
            cpm::stamp_message(o, now, 0);
            (void)seen.write(o);
            RangeSensors r;
            r.vehicle_id(uint8_t(id));
            r.front(1.0);
            cpm::stamp_message(r, now, 0);
            (void)ranges.write(r);
        }
    };
    auto drive = [&](double s) {  // 50 Hz on an absolute schedule
        auto next = std::chrono::steady_clock::now();
        const auto end = next + std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(s));
        while (next < end) {
            publish();
            next += 20ms;
            std::this_thread::sleep_until(next);
        }
    };
    drive(2.0);  // warm-up: discovery, the watchers connected, the monitor's first snapshots
    const double cpu0 = cpu_seconds(monitor_pid);
    const auto t0 = std::chrono::steady_clock::now();
    measuring = true;
    drive(seconds);
    measuring = false;
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const double cpu1 = cpu_seconds(monitor_pid);
    done = true;
    drive(0.2);  // one more snapshot lets each watcher see `done` and leave
    for (auto& w : watchers) w.join();
    Result r;
    std::lock_guard lock(mutex);
    r.monitor = bench::stats_of(monitor_us);
    r.dds = bench::stats_of(dds_us);
    r.cpu_percent = 100.0 * (cpu1 - cpu0) / wall;
    r.updates_per_watcher = double(updates) / wall / std::max(1, c.watchers);
    return r;
}

const char* kHelp =
    "usage: bench_monitor [--seconds 10] [--domain 212]\n"
    "cpm monitor as its own process: create_stamp to a watcher's snapshot with 1 and 10 watchers, beside\n"
    "a plain cpm reader's latency, and the monitor's CPU with 20 cars at 50 Hz.\n"
    "  --seconds S  per case, after 2 s of warm-up\n";

int run(int argc, char** argv)
{
    const auto flags = cpm::cli::parse_flags(argc, argv, {{"--seconds", true}, {"--domain", true}}, "bench_monitor");
    const double seconds = cpm::cli::parse_number("--seconds", flags.get("--seconds", "10"), 1, 86400);
    const std::string domain = std::to_string(cpm::cli::parse_integer("--domain", flags.get("--domain", "212"), 0, 232));
    bench::print_machine("cpm monitor as its own process on domain " + domain + "; cars publish VehicleState, VehicleObservation and "
                         "RangeSensors at 50 Hz each; watchers are HTTP clients reading /api/stream on 127.0.0.1; " +
                         std::to_string(int(seconds)) + " s per case after 2 s of warm-up");
    const std::string out = "/tmp/bench_monitor_" + std::to_string(::getpid()) + ".out";
    cpm::ChildProcess monitor(
        {.argv = {cpm::sibling_executable("cpm"), "monitor", "--port", "0", "--dds_domain", domain}, .stdout_path = out, .stderr_path = out});
    int port = 0;
    for (int i = 0; i < 200 && port == 0; ++i) {
        std::ifstream in(out);
        const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        std::smatch m;
        if (std::regex_search(text, m, std::regex("http://127\\.0\\.0\\.1:([0-9]+)/"))) port = std::stoi(m[1]);
        std::this_thread::sleep_for(50ms);
    }
    if (port == 0) {
        std::fprintf(stderr, "bench_monitor: cpm monitor did not start (see %s)\n", out.c_str());
        return 1;
    }
    cpm::ParticipantOptions po;
    po.domain_id = std::stoi(domain);
    po.name = "bench_monitor";
    cpm::Participant participant(po);

    std::printf("\n%-28s %10s %10s %10s %10s %12s %10s\n", "case", "p50 ms", "p99 ms", "DDS p50", "DDS p99", "updates/s", "CPU %");
    bool met = true;
    for (const Case c : {Case{1, 1}, Case{1, 10}, Case{20, 1}, Case{20, 10}}) {
        const Result r = run_case(c, port, monitor.pid(), participant, seconds);
        char label[64];
        std::snprintf(label, sizeof label, "%d car(s), %d watcher(s)", c.cars, c.watchers);
        std::printf("%-28s %10.2f %10.2f %10.3f %10.3f %12.1f %10.1f\n", label, r.monitor.p50 * 1e-3, r.monitor.p99 * 1e-3, r.dds.p50 * 1e-3,
                    r.dds.p99 * 1e-3, r.updates_per_watcher, r.cpu_percent);
        std::fflush(stdout);
        met = met && r.monitor.p99 <= 50'000 && (c.cars != 20 || r.cpu_percent <= 10.0);
        bench::record({"monitor", std::string(label) + ": create_stamp -> watcher p99", "ms", r.monitor.p99 * 1e-3, "plain cpm reader (DDS floor)",
                       r.dds.p99 * 1e-3, "<= 50 ms", r.monitor.p99 <= 50'000 ? 1 : 0});
        bench::record({"monitor", std::string(label) + ": monitor CPU", "% of a core", r.cpu_percent, "", 0,
                       c.cars == 20 ? "<= 10 %" : "", c.cars == 20 ? (r.cpu_percent <= 10.0 ? 1 : 0) : -1});
    }
    std::printf("\ntargets: p99 <= 50 ms (every case), monitor CPU <= 10 %% of one core (20 cars, 1 and 10 watchers): %s\n", met ? "met" : "NOT met");
    monitor.stop();
    ::unlink(out.c_str());
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "bench_monitor", kHelp, run); }
