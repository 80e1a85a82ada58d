// The simulated car's loop, measured:
//  1. one car (firmware_sim + vehicle_bridge over a pty): the bridge's CPU per 50 Hz cycle next
//     to the simulator's, and the command latency from a VehicleCommandDirect written to the
//     motor PWM the simulator's controller holds (its --trace-pwm);
//  2. capacity: N cars at once (`cpm vehicle sim --count N`: all cars in one simulator and one
//     bridge process; and with --process-per-car, a pair of processes per car), every car commanded; a cycle
//     counts as missed when a car published no VehicleState for a 20 ms slot (its
//     create_stamp is the controller's measurement time), or published it more than half a
//     period after the measurement (valid_after_stamp - create_stamp - 1 ms of expected delivery).
//
//   bench_vehicle [--seconds 10] [--cars 4,8,12,16,20,24] [--cars-per-car 2,4,6,8,10,12] [--domain 210]
#include "bench_common.hpp"

#include <cpm/CommandLine.hpp>
#include <cpm/Participant.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/percentile.hpp>
#include <cpm/stamp_message.hpp>

#include <VehicleCommandDirect.h>
#include <VehicleCommandSpeedCurvature.h>
#include <VehicleState.h>

#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <map>
#include <set>
#include <random>
#include <sstream>
#include <thread>
#include <unistd.h>

namespace {

using namespace std::chrono_literals;

std::string file_text(const std::string& path)
{
    std::ifstream in(path);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

/// utime + stime of a process in microseconds (from /proc/PID/stat).
double process_cpu_us(int pid)
{
    std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
    std::string text((std::istreambuf_iterator<char>(in)), {});
    std::istringstream fields(text.substr(text.rfind(')') + 2));
    std::string f;
    unsigned long long utime = 0, stime = 0;
    for (int i = 3; i <= 15 && fields >> f; ++i) {
        if (i == 14) utime = std::stoull(f);
        if (i == 15) stime = std::stoull(f);
    }
    return double(utime + stime) * 1e6 / double(sysconf(_SC_CLK_TCK));
}

/// Busy fraction of all cores over an interval (from /proc/stat).
struct CpuMeter
{
    unsigned long long busy = 0, total = 0;
    void sample(unsigned long long& b, unsigned long long& t)
    {
        std::ifstream in("/proc/stat");
        std::string cpu;
        in >> cpu;
        unsigned long long v, idle = 0;
        b = t = 0;
        for (int i = 0; i < 8 && in >> v; ++i) {
            t += v;
            if (i == 3 || i == 4) idle += v;
        }
        b = t - idle;
    }
    void start() { sample(busy, total); }
    double stop()
    {
        unsigned long long b, t;
        sample(b, t);
        return double(b - busy) / double(std::max(1ull, t - total));
    }
};

std::vector<nlohmann::json> json_lines(const std::string& text)
{
    std::vector<nlohmann::json> out;
    std::istringstream in(text);
    for (std::string line; std::getline(in, line);) {
        if (line.empty() || line[0] != '{') continue;
        try {
            out.push_back(nlohmann::json::parse(line));
        } catch (const nlohmann::json::exception&) {
        }
    }
    return out;
}

bool wait_for_line(const std::string& path, const std::string& prefix, std::string& line_out, std::chrono::seconds timeout)
{
    auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
        std::istringstream in(file_text(path));
        for (std::string line; std::getline(in, line);) {
            if (line.rfind(prefix, 0) == 0) {
                line_out = line;
                return true;
            }
        }
        std::this_thread::sleep_for(10ms);
    }
    return false;
}

void one_car(cpm::Participant& participant, const std::vector<std::string>& env, int seconds)
{
    const std::string sim_out = "/tmp/bench_vehicle_sim.out", bridge_out = "/tmp/bench_vehicle_bridge.out";
    std::remove(sim_out.c_str());  // never read the device line of an earlier run
    std::remove(bridge_out.c_str());
    auto sim = bench::spawn({cpm::sibling_executable("firmware_sim"), "--vehicle_id", "1", "--trace-pwm"}, env, sim_out, "/tmp/bench_vehicle_sim.err");
    std::string device;
    if (!wait_for_line(sim_out, "device: ", device, 10s)) {
        std::fprintf(stderr, "bench_vehicle: firmware_sim did not start\n");
        std::exit(1);
    }
    auto bridge = bench::spawn({cpm::sibling_executable("vehicle_bridge"), "--vehicle_id", "1", "--device", device.substr(8)}, env, bridge_out,
                              "/tmp/bench_vehicle_bridge.err");
    cpm::ReaderAbstract<VehicleState> states(participant, "vehicleState");
    cpm::Writer<VehicleCommandDirect> writer(participant, "vehicleCommandDirect");
    if (!states.wait_for_data(10s) || !writer.wait_for_matched(1, 10s))
        std::fprintf(stderr, "bench_vehicle: the car did not answer within 10 s\n");
    std::this_thread::sleep_for(500ms);

    // A new throttle every 100-120 ms (random phase against the car's 20 ms cycle), never the
    // same PWM twice in a row.
    std::mt19937 rng(1);
    std::vector<std::pair<uint64_t, int>> writes;  // (time, pwm)
    VehicleCommandDirect command;
    command.vehicle_id(1);
    double cpu_sim0 = process_cpu_us(sim.pid()), cpu_bridge0 = process_cpu_us(bridge.pid());
    auto t_end = std::chrono::steady_clock::now() + std::chrono::seconds(seconds);
    for (int k = 0; std::chrono::steady_clock::now() < t_end; ++k) {
        int pwm = 100 + (k % 2) * 100 + (k % 50) * 4;
        command.motor_throttle(pwm / 1000.0);
        uint64_t now = cpm::get_time_ns();
        cpm::stamp_message(command, now, 0);
        (void)writer.write(command);
        writes.emplace_back(now, pwm);
        std::this_thread::sleep_for(100ms + std::chrono::microseconds(rng() % 20'000));
    }
    double cpu_sim = process_cpu_us(sim.pid()) - cpu_sim0, cpu_bridge = process_cpu_us(bridge.pid()) - cpu_bridge0;
    bridge.signal(SIGTERM);
    sim.signal(SIGTERM);
    bench::wait_child(bridge, 10);
    bench::wait_child(sim, 10);

    // Match each write with the first trace line after it that shows its PWM.
    std::vector<std::pair<uint64_t, int>> trace;
    std::istringstream in(file_text(sim_out));
    for (std::string word; in >> word;) {
        if (word != "pwm") continue;
        unsigned long long t;
        int mode, pwm;
        in >> t >> mode >> pwm;
        trace.emplace_back(t, pwm);
    }
    std::vector<double> latency_us;
    size_t lost = 0;
    for (auto [t, pwm] : writes) {
        auto it = std::find_if(trace.begin(), trace.end(), [&](auto& e) { return e.first > t && e.second == pwm; });
        if (it == trace.end() || it->first - t > 200'000'000ull) {
            ++lost;
            continue;
        }
        latency_us.push_back(double(it->first - t) * 1e-3);
    }
    auto bridge_stats = json_lines(file_text(bridge_out));
    auto sim_stats = json_lines(file_text(sim_out));
    if (bridge_stats.empty() || sim_stats.empty()) {
        std::fprintf(stderr, "bench_vehicle: no statistics from the car's processes\n");
        std::exit(1);
    }
    double cycles = bridge_stats[0]["cycles"].get<double>();
    std::printf("\n-- one car, %d s: cost per 50 Hz cycle (µs of CPU)\n", seconds);
    std::printf("%-44s %9s %9s\n", "", "p50", "p99");
    std::printf("%-44s %9.1f %9.1f\n", "vehicle_bridge loop thread (per cycle)", bridge_stats[0]["cycle_cpu_us_p50"].get<double>(),
                bridge_stats[0]["cycle_cpu_us_p99"].get<double>());
    std::printf("%-44s %9.1f  (all threads, DDS included)\n", "vehicle_bridge process, mean per cycle", cpu_bridge / cycles);
    std::printf("%-44s %9.1f  (reference: 5 model steps, 3 rangers, 1 DDS write)\n",
                "firmware_sim process, mean per cycle", cpu_sim / double(sim_stats[0]["state_packets"].get<double>()));
    bench::print_header("-- command latency: VehicleCommandDirect written -> PWM held by the simulated controller (µs)");
    bench::print_row("cpm (DDS + wait for the next 50 Hz cycle + pty)", bench::stats_of(latency_us));
    std::printf("%-44s %9.1f  (a uniform wait for the next cycle alone: p50 10000, p99 19800)\n", "cycle period / 2", 10000.0);
    std::printf("commands written %zu, not seen within 200 ms: %zu\n", writes.size(), lost);
}

struct CapacityResult
{
    double missed_fraction = 0, cpu_busy = 0;
    uint64_t expected = 0, received = 0, absent = 0, late = 0;
    std::vector<double> publish_delay_us;  ///< measurement -> publication (valid_after - create, less the expected delivery)
    std::vector<double> arrival_delay_us;  ///< measurement -> in the consumer's hands (its clock at take - create)
};

CapacityResult capacity(cpm::Participant& participant, const std::vector<std::string>& env, int cars, int seconds, bool per_car,
                        bool realtime = false)
{
    const std::string out = "/tmp/bench_vehicle_fleet.out";
    std::remove(out.c_str());
    std::vector<std::string> argv{cpm::sibling_executable("cpm"), "vehicle", "sim", "--id", "1", "--count", std::to_string(cars)};
    if (per_car) argv.push_back("--process-per-car");
    if (realtime) argv.push_back("--realtime");
    auto fleet = bench::spawn(argv, env, out, "/tmp/bench_vehicle_fleet.err");
    cpm::ReaderAbstract<VehicleState> states(participant, "vehicleState", {.keep_all = true});
    cpm::Writer<VehicleCommandSpeedCurvature> writer(participant, "vehicleCommandSpeedCurvature");
    std::map<int, std::vector<uint64_t>> stamps;
    struct Delays
    {
        uint64_t created, to_publication, to_arrival;  ///< create_stamp; valid_after - create; taken here - create
    };
    std::vector<Delays> delays;
    std::atomic<bool> stop{false};
    std::thread commander([&] {
        VehicleCommandSpeedCurvature c;
        c.speed(0.3);
        c.curvature(1.0);
        while (!stop) {
            for (int id = 1; id <= cars; ++id) {
                c.vehicle_id(uint8_t(id));
                cpm::stamp_message(c, cpm::get_time_ns(), 0);
                (void)writer.write(c);
            }
            std::this_thread::sleep_for(50ms);
        }
    });
    // Wait until every car publishes, then measure a window.
    auto deadline = std::chrono::steady_clock::now() + 30s;
    std::map<int, bool> seen;
    while (int(seen.size()) < cars && std::chrono::steady_clock::now() < deadline) {
        for (auto& s : states.take()) seen[s.vehicle_id()] = true;
        std::this_thread::sleep_for(10ms);
    }
    std::this_thread::sleep_for(2s);
    states.take();
    CpuMeter cpu;
    cpu.start();
    uint64_t t0 = cpm::get_time_ns(), t1 = t0 + uint64_t(seconds) * 1'000'000'000ull;
    while (cpm::get_time_ns() < t1 + 200'000'000ull) {
        if (!states.wait_for_data(5ms)) continue;
        const uint64_t arrived = cpm::get_time_ns();
        for (auto& s : states.take()) {
            uint64_t created = s.header().create_stamp().nanoseconds();
            stamps[s.vehicle_id()].push_back(created);
            delays.push_back({created, s.header().valid_after_stamp().nanoseconds() - created, arrived > created ? arrived - created : 0});
        }
    }
    CapacityResult r;
    r.cpu_busy = cpu.stop();
    stop = true;
    commander.join();
    fleet.signal(SIGINT);
    bench::wait_child(fleet, 20);

    const uint64_t period = 20'000'000, expected_delivery = 1'000'000;
    for (const auto& d : delays) {
        if (d.created < t0 || d.created >= t1) continue;
        uint64_t publish = d.to_publication > expected_delivery ? d.to_publication - expected_delivery : 0;
        r.publish_delay_us.push_back(double(publish) * 1e-3);
        r.late += publish > period / 2;
        r.arrival_delay_us.push_back(double(d.to_arrival) * 1e-3);
    }
    for (int id = 1; id <= cars; ++id) {
        auto& v = stamps[id];
        std::sort(v.begin(), v.end());
        std::vector<uint64_t> in_window;
        for (auto t : v) {
            if (t >= t0 && t < t1) in_window.push_back(t);
        }
        r.expected += uint64_t(seconds) * 50;
        r.received += in_window.size();
        if (in_window.empty()) {
            r.absent += uint64_t(seconds) * 50;
            continue;
        }
        // The car's cycle phase (its simulator ticks at fixed times); a cycle is missed when no
        // state lands within half a period of its slot.
        std::vector<uint64_t> phases;
        for (auto t : in_window) phases.push_back(t % period);
        const uint64_t phase = cpm::percentile(phases, 0.5);
        std::set<uint64_t> slots;
        for (auto t : in_window) slots.insert((t - phase + period / 2) / period);
        const uint64_t first = (t0 - phase + period - 1) / period, last = (t1 - phase - 1) / period;
        uint64_t hit = 0;
        for (auto k : slots) hit += (k >= first && k <= last);
        r.absent += (last - first + 1) - hit;
    }
    r.missed_fraction = double(r.absent + r.late) / double(std::max<uint64_t>(1, r.expected));
    return r;
}

const char* kHelp =
    "usage: bench_vehicle [--seconds 10] [--cars 4,8,12,16,20,24] [--cars-per-car 2,4,6,8,10,12] [--domain 210]\n"
    "The simulated car's loop: the bridge's CPU per cycle and the command latency for one car, then how\n"
    "many cars this machine runs with under 1 % missed cycles.\n"
    "  --seconds S          per case\n"
    "  --cars A,B,...       fleet sizes with all cars in one simulator and one bridge process\n"
    "  --cars-per-car A,... fleet sizes with a simulator and bridge process pair per car\n"
    "  --loaded-cars N      then N cars in one process with a busy loop on every core, normal against\n"
    "                       --realtime (default 8; 0: not run)\n"
    "(--role busy: the spinning process it starts itself)\n";

int run(int argc, char** argv)
{
    const auto flags = cpm::cli::parse_flags(
        argc, argv, {{"--seconds", true}, {"--domain", true}, {"--cars", true}, {"--cars-per-car", true}, {"--loaded-cars", true}, {"--role", true}},
        "bench_vehicle");
    bench::spin_if_asked(flags.get("--role", "main"));
    const int loaded_cars = int(cpm::cli::parse_integer("--loaded-cars", flags.get("--loaded-cars", "8"), 0, 255));
    const int seconds = int(cpm::cli::parse_integer("--seconds", flags.get("--seconds", "10"), 1, 86400));
    const int domain = int(cpm::cli::parse_integer("--domain", flags.get("--domain", "210"), 0, 232));
    auto sizes = [&](const char* flag, const char* fallback) {
        const auto listed = bench::integer_list(flag, flags.get(flag, fallback), 1, 255);
        return std::vector<int>(listed.begin(), listed.end());
    };
    const std::vector<int> one_process = sizes("--cars", "4,8,12,16,20,24"), per_car = sizes("--cars-per-car", "2,4,6,8,10,12");

    bench::print_machine("50 Hz state packets, 250 Hz model, " + std::to_string(seconds) + " s per case, domain " +
                         std::to_string(domain));
    const std::vector<std::string> env{"CPM_DOMAIN_ID=" + std::to_string(domain)};
    cpm::ParticipantOptions options;
    options.domain_id = domain;
    options.name = "bench_vehicle";
    cpm::Participant participant(options);

    one_car(participant, env, seconds);

    // A fleet size counts only when it and every smaller size measured passed: one that fails
    // below the target is not rescued by a larger one that happened to pass.
    auto capacity_table = [&](const std::vector<int>& fleet_sizes, bool process_per_car, int target) {
        std::printf("\n-- capacity: N simulated cars, %s, all commanded\n",
                    process_per_car ? "a firmware_sim + vehicle_bridge pair per car (--process-per-car)"
                                    : "all in one firmware_sim and one vehicle_bridge process");
        std::printf("(absent: a 20 ms slot of a car without its VehicleState; late: published > 10 ms after the\n"
                    " controller measured it; publish: measurement -> publication, µs; arrive: measurement -> taken by\n"
                    " this consumer, µs; the cars' stderr: /tmp/bench_vehicle_fleet.err)\n");
        std::printf("%6s %9s %9s %7s %6s %9s %11s %11s %11s %11s %9s\n", "cars", "expected", "received", "absent", "late",
                    "missed %", "publish p50", "publish p99", "arrive p50", "arrive p99", "CPU busy");
        int largest = 0;
        bool all_so_far = true, target_measured = false;
        std::string passed;
        for (int cars : fleet_sizes) {
            auto r = capacity(participant, env, cars, seconds, process_per_car);
            auto publish = bench::stats_of(r.publish_delay_us), arrive = bench::stats_of(r.arrival_delay_us);
            std::printf("%6d %9llu %9llu %7llu %6llu %8.3f%% %11.0f %11.0f %11.0f %11.0f %8.0f%%\n", cars,
                        (unsigned long long)r.expected, (unsigned long long)r.received, (unsigned long long)r.absent,
                        (unsigned long long)r.late, r.missed_fraction * 100, publish.p50, publish.p99, arrive.p50, arrive.p99,
                        r.cpu_busy * 100);
            std::fflush(stdout);
            const bool ok = r.missed_fraction < 0.01;
            if (ok) passed += (passed.empty() ? "" : ", ") + std::to_string(cars);
            all_so_far = all_so_far && ok;
            if (all_so_far) largest = cars;
            target_measured = target_measured || cars >= target;
        }
        const bool met = target_measured && largest >= target;
        std::printf("fleets with < 1 %% missed cycles: %s; every size up to %d cars passed (target: every size up to %d: %s)\n",
                    passed.empty() ? "none" : passed.c_str(), largest, target,
                    !target_measured ? "not measured" : met ? "met" : "not met");
        bench::record({"vehicle", process_per_car ? "cars under 1 % missed, a process pair per car" : "cars under 1 % missed, one process",
                       "cars", double(largest), "", 0, ">= " + std::to_string(target) + " cars", target_measured ? int(met) : -1});
        return largest;
    };
    const int one = capacity_table(one_process, false, 20);
    const int pairs = capacity_table(per_car, true, 10);
    std::printf("\nlargest fleet with every size up to it under 1 %% missed: one process %d cars, a process pair per car %d cars\n",
                one, pairs);
    if (loaded_cars > 0) {
        // A car's loop in real time keeps its cycles while every core spins at normal priority.
        std::printf("\n-- %d cars in one process, a busy loop on every core: normal against --realtime\n", loaded_cars);
        std::printf("%10s %9s %9s %7s %6s %9s\n", "mode", "expected", "received", "absent", "late", "missed %");
        std::map<bool, double> missed;
        for (const bool realtime : {false, true}) {
            const auto r = [&] {
                const bench::BusyLoops spinners(bench::BusyLoops::every_core());
                return capacity(participant, env, loaded_cars, seconds, false, realtime);
            }();
            std::printf("%10s %9llu %9llu %7llu %6llu %8.3f%%\n", realtime ? "realtime" : "normal", (unsigned long long)r.expected,
                        (unsigned long long)r.received, (unsigned long long)r.absent, (unsigned long long)r.late, r.missed_fraction * 100);
            std::fflush(stdout);
            missed[realtime] = r.missed_fraction * 100;
        }
        bench::record({"vehicle", std::to_string(loaded_cars) + " cars, every core busy, missed cycles in real time", "%", missed[true],
                       "the same in normal mode", missed[false], "< 1 % and <= peer", int(missed[true] < 1 && missed[true] <= missed[false])});
    }
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "bench_vehicle", kHelp, run); }
