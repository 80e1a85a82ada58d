// bench_startup: how long a lab run takes to come up across hosts against the same run on one
// host. Three network namespaces joined by veth pairs stand for three computers, each with its
// own sshd (as the tests make them; needs root). The run (`cpm lab run`, on the central host)
// has two cars, car 5 with its state machine; on three hosts each car runs on a car host, the
// history on the central one; on one host everything runs on the central host. Start-up: from
// launching `cpm lab run` until the central recording holds a state of every car (the lab is
// driving). Runs alternate, each `--runs` times; the medians and their ratio.
//   bench_startup [--runs 3] [--dds_domain N]
#include "../common/bench_common.hpp"

#include <cpm/ChildProcess.hpp>
#include <cpm/CommandLine.hpp>
#include <cpm/HistoryClient.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/init.hpp>
#include <cpm_test/Hosts.hpp>
#include <cpm_test/Process.hpp>

#include <VehicleState.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace fs = std::filesystem;

namespace {

const char* kHelp =
    "usage: bench_startup [--runs 3] [--dds_domain N]\n"
    "Start-up of a two-car lab run across three hosts (network namespaces with their own sshd, as\n"
    "root) against the same run on one host: from `cpm lab run` until the central recording holds\n"
    "a state of every car. Prints each run and the medians.\n"
    "  --runs N        runs of each (default 3)\n"
    "  --dds_domain N  the runs' domain (default CPM_DOMAIN_ID, else 0)\n";

const std::vector<int> kCars{5, 6};

/// The scenario: `across` puts each car on a car host of its own and the history on the central one.
std::string scenario(const cpm_test::NamespaceHosts& hosts, bool across, const std::string& domain)
{
    const std::string root = CPM_SOURCE_DIR;
    std::string y = "name: startup\ntime: real\nduration: 3s\ndomain: " + domain + "\nworld: " + root + "/scenarios/maps/gates.json\n";
    std::string car_a, car_b;
    if (across) {
        y += "hosts:\n  central: {address: " + hosts.address(0) + "}\n";
        for (size_t h : {1u, 2u}) {
            const std::string name = h == 1 ? "car_a" : "car_b";
            y += "  " + name + ": {address: " + hosts.address(h) + ", ssh: " + name + ", cpm: " + cpm_test::cpm_prefix() + "}\n";
        }
        y += "ssh_config: " + hosts.ssh_config() + "\nhistory: {host: central}\n";
        car_a = ", host: car_a", car_b = ", host: car_b";
    }
    y += "vehicles:\n  - {id: 5" + car_a + ", start: [0.0, 0.0, 0.3], fsm: " + root + "/scenarios/fsm/gates.json}\n"
         "  - {id: 6" + car_b + ", start: [0.0, 0.6, 0.3]}\n";
    return y;
}

/// Seconds from the launch until every car's first state was recorded; < 0 when the run failed.
double start_up(const cpm_test::NamespaceHosts& hosts, bool across, const std::string& domain, const fs::path& dir, int n)
{
    const fs::path file = dir / ((across ? "across_" : "one_") + std::to_string(n) + ".yaml");
    const fs::path out = dir / ((across ? "across_run_" : "one_run_") + std::to_string(n));
    std::ofstream(file) << scenario(hosts, across, domain);
    const uint64_t t0 = cpm::get_time_ns();
    cpm::ChildProcess run({.argv = hosts.in(0, {cpm_test::built_program("cpm"), "lab", "run", file.string(), "--out", out.string(), "--monitor", "off"}),
                           .stdout_path = out.string() + ".out",
                           .stderr_path = out.string() + ".err"});
    const auto end = run.wait(std::chrono::seconds(120));
    if (!end || !end->ok()) {
        std::printf("  run %s failed; see %s.err\n", out.c_str(), out.c_str());
        return -1;
    }
    auto recording = cpm::HistoryClient::open_recording((out / "recording.db").string());
    uint64_t up = 0;
    for (int car : kCars) {
        const auto states = recording.range_of<VehicleState>("vehicleState", car, 0, UINT64_MAX, cpm::HistoryBy::commit, 1);
        if (states.samples.empty()) return -1;
        up = std::max(up, states.samples.front().commit_ns);
    }
    return double(up - t0) * 1e-9;
}

double median(std::vector<double> v)
{
    std::sort(v.begin(), v.end());
    return v.empty() ? 0 : v[v.size() / 2];
}

int run(int argc, char** argv)
{
    const auto flags = cpm::cli::parse_flags(argc, argv, {{"--runs", true}}, "bench_startup");
    const int runs = int(cpm::cli::parse_number("--runs", flags.get("--runs", "3"), 1, 100));
    cpm::init(argc, argv);
    const std::string domain = std::to_string(cpm::init_settings().domain_id);
    cpm_test::NamespaceHosts hosts({"central", "car_a", "car_b"});
    if (!hosts.why_not().empty()) {
        std::printf("not run: %s\n", hosts.why_not().c_str());
        return 1;
    }
    bench::print_machine("two cars (car 5 with its state machine), real time; three hosts: each car on a car host, the history "
                         "on the central host, over ssh; one host: everything on the central host; domain " + domain);
    const fs::path dir = fs::temp_directory_path() / ("cpm_bench_startup_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    std::vector<double> one, across;
    for (int n = 0; n < runs; ++n) {
        for (bool a : {false, true}) {
            const double s = start_up(hosts, a, domain, dir, n);
            std::printf("  run %d, %s: %.2f s\n", n + 1, a ? "three hosts" : "one host", s);
            if (s < 0) return 1;
            (a ? across : one).push_back(s);
        }
    }
    const double m1 = median(one), m3 = median(across);
    std::printf("\nstart-up until every car's first state is recorded (median of %d): one host %.2f s, three hosts %.2f s (%.2fx, +%.2f s)\n",
                runs, m1, m3, m3 / m1, m3 - m1);
    bench::record({.bench = "startup", .what = "two cars until recorded, three hosts", .unit = "s", .cpm = m3, .peer = "the same run on one host", .peer_value = m1});
    if (!std::getenv("BENCH_KEEP")) fs::remove_all(dir);
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "bench_startup", kHelp, run); }
