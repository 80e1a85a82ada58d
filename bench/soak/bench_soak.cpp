// bench_soak: a whole lab for a long time, watched from outside. `cpm lab run` of ten simulated
// cars on the intersection's lanes under central_routing in real time, with the history
// recording every topic, the monitor and a parameter server. Every 10 s it samples each
// process of the run (resident memory, open file descriptors) and /dev/shm (files, bytes).
// At the end, against the targets:
//   - every process's RSS flat after the warm-up (the first two minutes: the history fills its
//     60 s window first): growth < 5 %;
//   - no file descriptor and no /dev/shm growth after the warm-up, nothing left there after the run;
//   - missed deadlines < 1 % of the timers' ticks (the simulator's 250 Hz, the planner's 2.5 Hz);
//   - no sample of a reliable topic lost (the recording's per-object counts of samples sent and
//     never received), none dropped by the recording.
// With --hosts (root) the lab runs across three hosts, network namespaces each with its own
// sshd as the tests make them: the cars' simulator on car_a, central_routing on car_b, the run,
// the history, the monitor and the parameter server on the central host; every car's states and
// commands cross the links. The processes on the car hosts are sampled too.
//   bench_soak [--minutes 10] [--hosts] [--dds_domain N]
#include "../common/bench_common.hpp"

#include <cpm/ChildProcess.hpp>
#include <cpm/CommandLine.hpp>
#include <cpm/init.hpp>
#include <cpm/topics.hpp>
#include <cpm/vehicle/VehicleModel.hpp>

#include <cpm_test/Hosts.hpp>

#include <nlohmann/json.hpp>

#include <dirent.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <thread>

namespace fs = std::filesystem;

namespace {

struct ProcessSample
{
    std::string name;
    double rss_mib = 0;
    int fds = 0;
};

/// A process's resident memory and open descriptors.
ProcessSample sample_of(int pid, const std::string& name)
{
    ProcessSample s;
    s.name = name;
    std::ifstream statm("/proc/" + std::to_string(pid) + "/statm");
    long pages = 0, resident = 0;
    statm >> pages >> resident;
    s.rss_mib = double(resident) * double(::sysconf(_SC_PAGESIZE)) / (1024.0 * 1024.0);
    std::error_code ec;
    for (auto it = fs::directory_iterator("/proc/" + std::to_string(pid) + "/fd", ec); !ec && it != fs::directory_iterator(); ++it) ++s.fds;
    return s;
}

/// Every process below `root` (its children, theirs, …), by pid.
std::map<int, ProcessSample> descendants(int root)
{
    std::map<int, int> parent;
    std::map<int, std::string> comm;
    for (const auto& entry : fs::directory_iterator("/proc")) {
        const std::string name = entry.path().filename();
        if (name.find_first_not_of("0123456789") != std::string::npos) continue;
        std::ifstream stat(entry.path() / "stat");
        std::string line;
        if (!std::getline(stat, line)) continue;
        const auto close = line.rfind(')');
        if (close == std::string::npos) continue;
        std::istringstream rest(line.substr(close + 2));
        char state = 0;
        int ppid = 0;
        rest >> state >> ppid;
        parent[std::stoi(name)] = ppid;
        comm[std::stoi(name)] = line.substr(line.find('(') + 1, close - line.find('(') - 1);
    }
    std::map<int, ProcessSample> out;
    for (const auto& [pid, ppid] : parent) {
        int p = ppid;
        while (p > 1 && p != root) p = parent.count(p) ? parent[p] : 0;
        if (p == root) out[pid] = sample_of(pid, comm[pid]);
    }
    return out;
}

/// Files and bytes in /dev/shm.
std::pair<int, double> shm_usage()
{
    int files = 0;
    double bytes = 0;
    std::error_code ec;
    for (auto it = fs::directory_iterator("/dev/shm", ec); !ec && it != fs::directory_iterator(); ++it) {
        ++files;
        struct stat st {};
        if (::stat(it->path().c_str(), &st) == 0) bytes += double(st.st_blocks) * 512.0;
    }
    return {files, bytes};
}

std::string run_command(const std::vector<std::string>& argv, const std::string& out_path)
{
    cpm::ChildProcess child({.argv = argv, .stdout_path = out_path, .stderr_path = out_path + ".err"});
    (void)child.wait(std::chrono::seconds(120));
    std::ifstream in(out_path);
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

/// The run's processes on a host of the namespace hosts (cpm's programs, not `cpm host run`).
std::map<int, ProcessSample> programs_on(const cpm_test::NamespaceHosts& hosts, size_t host, const std::string& tag)
{
    std::map<int, ProcessSample> out;
    for (int pid : hosts.pids(host)) {
        const std::string cmd = cpm_test::command_line(pid);
        if (cmd.rfind(cpm_test::cpm_prefix(), 0) != 0 || cmd.find("/bin/cpm host run ") != std::string::npos) continue;
        out[pid] = sample_of(pid, tag + ":" + fs::path(cmd.substr(0, cmd.find(' '))).filename().string());
    }
    return out;
}

const char* kHelp =
    "usage: bench_soak [--minutes 10] [--hosts] [--dds_domain N]\n"
    "A whole lab (ten simulated cars, central routing, the history recording every topic, the monitor)\n"
    "for a long time, watched from outside: memory, file descriptors and /dev/shm every 10 s, missed\n"
    "deadlines and lost samples, against their targets.\n"
    "  --minutes M     how long the lab runs\n"
    "  --hosts         across three hosts (network namespaces with their own sshd; root): the cars on\n"
    "                  car_a, central_routing on car_b, the rest on the central host\n"
    "  --dds_domain N  its domain (default CPM_DOMAIN_ID, else 0)\n";

int run(int argc, char** argv)
{
    const auto flags = cpm::cli::parse_flags(argc, argv, {{"--minutes", true}, {"--hosts", false}}, "bench_soak");
    std::optional<cpm_test::NamespaceHosts> hosts;
    if (flags.has("--hosts")) {
        hosts.emplace(std::vector<std::string>{"central", "car_a", "car_b"});
        if (!hosts->why_not().empty()) {
            std::printf("not run: %s\n", hosts->why_not().c_str());
            return 1;
        }
    }
    const double minutes = cpm::cli::parse_number("--minutes", flags.get("--minutes", "10"), 0.1, 100'000);
    cpm::init(argc, argv);  // --dds_domain is cpm's own flag
    const std::string domain = std::to_string(cpm::init_settings().domain_id);
    // The history fills its 60 s window first: its memory grows until then, by design.
    const double warm_up_s = std::min(120.0, minutes * 60.0 / 5.0);
    const std::string bin = cpm::executable_dir();
    const std::string root = CPM_SOURCE_DIR;
    const fs::path dir = fs::temp_directory_path() / ("cpm_soak_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    std::ofstream(dir / "params.json") << "{\"soak\": 1}\n";
    std::ostringstream yaml;
    yaml << "name: soak\ntime: real\nduration: " << minutes * 60.0 << "s\nlanes: " << root << "/scenarios/lanes/intersection.json\n"
         << "vehicles:\n";
    const std::string car_host = hosts ? ", host: car_a" : "";
    for (int id = 1; id <= 10; ++id) yaml << "  - {id: " << id << car_host << "}\n";
    if (hosts) {
        yaml << "hosts:\n  central: {address: " << hosts->address(0) << "}\n";
        for (size_t h : {1u, 2u}) {
            const std::string name = h == 1 ? "car_a" : "car_b";
            yaml << "  " << name << ": {address: " << hosts->address(h) << ", ssh: " << name << ", cpm: " << cpm_test::cpm_prefix() << "}\n";
        }
        yaml << "ssh_config: " << hosts->ssh_config() << "\nhistory: {host: central}\n";
    }
    yaml << "routing: {enabled: true, seed: 1, period: 400ms" << (hosts ? ", host: car_b" : "") << "}\nrecord: {topics: [\"*\"]}\nparameters: " << (dir / "params.json").string()
         << "\nmonitor: " << 18000 + ::getpid() % 1000 << "\n";
    std::ofstream(dir / "soak.yaml") << yaml.str();

    bench::print_machine("ten simulated cars, central_routing (400 ms), cpm_history recording every topic, monitor, parameter "
                         "server; real time, " + std::to_string(minutes) + " min, domain " + domain +
                         (hosts ? "; across three hosts: the cars on car_a, central_routing on car_b, the rest central" : ""));
    const std::string out = (dir / "run").string();
    const auto shm_before = shm_usage();  // what the run must leave as it found it
    std::vector<std::string> lab_argv{bin + "/cpm", "lab", "run", (dir / "soak.yaml").string(), "--out", out, "--dds_domain", domain};
    if (hosts) lab_argv = hosts->in(0, lab_argv);  // ip netns exec: the same process, in the central host's namespace
    cpm::ChildProcess lab({.argv = lab_argv,
                           .stdout_path = (dir / "lab.out").string(),
                           .stderr_path = (dir / "lab.err").string()});

    // Samples every 10 s: per process name (one process per name in this lab) and /dev/shm.
    struct Row
    {
        double t_s;
        std::map<std::string, ProcessSample> processes;
        int shm_files;
        double shm_mib;
    };
    std::vector<Row> rows;
    const auto t0 = std::chrono::steady_clock::now();
    while (lab.running()) {
        const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        Row row{t, {}, 0, 0};
        auto processes = descendants(lab.pid());
        if (hosts) {
            for (size_t h : {1u, 2u}) processes.merge(programs_on(*hosts, h, h == 1 ? "car_a" : "car_b"));
        }
        for (const auto& [pid, s] : processes) row.processes[s.name + "[" + std::to_string(pid) + "]"] = s;
        const auto [files, bytes] = shm_usage();
        row.shm_files = files;
        row.shm_mib = bytes / (1024.0 * 1024.0);
        if (!row.processes.empty()) rows.push_back(row);
        for (int i = 0; i < 100 && lab.running(); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    const auto end = lab.wait(std::chrono::seconds(60));
    const int exit_code = end ? (end->ok() ? 0 : std::max(1, end->code)) : -1;
    std::printf("cpm lab run exited %d after %.0f s; its folder: %s\n", exit_code,
                std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), out.c_str());
    if (rows.size() < 3) {
        std::printf("too few samples (%zu): the run did not last\n", rows.size());
        return 1;
    }

    // The first row after the warm-up against the last row with the full lab (the last rows may
    // see the lab stopping).
    size_t warm = 0;
    while (warm + 1 < rows.size() && rows[warm].t_s < warm_up_s) ++warm;
    size_t last = rows.size() - 1;
    while (last > warm && rows[last].processes.size() < rows[warm].processes.size()) --last;
    bool ok = true;
    std::printf("\n%-34s %10s %10s %8s %6s %6s\n", "process", "RSS@warm", "RSS@end", "growth", "fds@w", "fds@e");
    double worst_growth = 0;
    int fd_growth = 0;
    for (const auto& [name, w] : rows[warm].processes) {
        const auto e = rows[last].processes.find(name);
        if (e == rows[last].processes.end()) continue;
        const double growth = (e->second.rss_mib - w.rss_mib) / w.rss_mib * 100.0;
        worst_growth = std::max(worst_growth, growth);
        fd_growth = std::max(fd_growth, e->second.fds - w.fds);
        std::printf("%-34s %8.1f M %8.1f M %7.2f%% %6d %6d\n", name.c_str(), w.rss_mib, e->second.rss_mib, growth, w.fds, e->second.fds);
    }
    // A process that grew: its memory over the whole run, to tell a leak from a late warm-up.
    for (const auto& [name, w] : rows[warm].processes) {
        const auto e = rows[last].processes.find(name);
        if (e == rows[last].processes.end() || (e->second.rss_mib - w.rss_mib) / w.rss_mib < 0.01) continue;
        std::printf("%s RSS (MiB) every 10 s:", name.c_str());
        for (const auto& row : rows)
            if (auto r = row.processes.find(name); r != row.processes.end()) std::printf(" %.1f", r->second.rss_mib);
        std::printf("\n");
    }
    std::printf("/dev/shm: %d files %.1f MiB after the warm-up (%.0f s), %d files %.1f MiB at %.0f s\n", rows[warm].shm_files,
                rows[warm].shm_mib, rows[warm].t_s, rows[last].shm_files, rows[last].shm_mib, rows[last].t_s);

    // Missed deadlines and losses, from the run's summary and its recording.
    std::ifstream summary_file(out + "/summary.json");
    const auto summary = nlohmann::json::parse(summary_file, nullptr, false);
    const double lab_s = summary.is_object() ? summary.value("lab_time_s", 0.0) : 0.0;
    const uint64_t missed = summary.is_object() ? summary.value("missed_deadlines", uint64_t(0)) : 0;
    const double ticks = lab_s * (cpm::vehicle::VehicleParameters{}.physics_rate + 2.5);
    const double missed_pct = ticks > 0 ? double(missed) / ticks * 100.0 : 100.0;
    const uint64_t dropped = summary.is_object() && summary.contains("recording") ? summary["recording"].value("dropped", uint64_t(0)) : 0;
    std::map<std::string, uint64_t> lost_by_topic;
    const std::string list = run_command({bin + "/cpm", "history", "--file", out + "/recording.db", "list", "--json"}, (dir / "list.json").string());
    std::istringstream lines(list);
    for (std::string line; std::getline(lines, line);) {
        const auto o = nlohmann::json::parse(line, nullptr, false);
        if (!o.is_object() || o.value("is_process", false)) continue;
        lost_by_topic[o.value("topic", "")] += o.value("samples_lost", uint64_t(0));
    }
    // Every process of the run and the command above have ended: their shared memory must be gone.
    const auto shm_after = shm_usage();
    std::printf("/dev/shm: %d files %.1f MiB before the run, %d files %.1f MiB after its processes ended\n", shm_before.first,
                shm_before.second / (1024.0 * 1024.0), shm_after.first, shm_after.second / (1024.0 * 1024.0));
    uint64_t reliable_lost = 0, best_effort_lost = 0;
    for (const auto& [topic, lost] : lost_by_topic) {
        const auto* spec = cpm::topics::find(topic);
        const bool reliable = spec != nullptr && spec->writer.reliable;
        (reliable ? reliable_lost : best_effort_lost) += lost;
        if (lost > 0) std::printf("lost on %s (%s): %llu\n", topic.c_str(), reliable ? "reliable" : "best effort", (unsigned long long)lost);
    }
    std::printf("missed deadlines: %llu of %.0f ticks (%.3f %%); recording dropped %llu; reliable samples lost %llu, best-effort "
                "samples lost %llu\n",
                (unsigned long long)missed, ticks, missed_pct, (unsigned long long)dropped, (unsigned long long)reliable_lost,
                (unsigned long long)best_effort_lost);

    auto target = [&](const char* what, bool met, const std::string& figure) {
        std::printf("%-40s %-28s %s\n", what, figure.c_str(), met ? "met" : "NOT MET");
        ok = ok && met;
    };
    std::printf("\n");
    char buf[64];
    std::snprintf(buf, sizeof buf, "worst %.2f %%", worst_growth);
    target("RSS growth after warm-up < 5 %", worst_growth < 5.0, buf);
    target("no fd growth", fd_growth <= 0, "max +" + std::to_string(fd_growth));
    target("no /dev/shm growth", rows[last].shm_files <= rows[warm].shm_files,
           std::to_string(rows[warm].shm_files) + " -> " + std::to_string(rows[last].shm_files) + " files");
    target("nothing left in /dev/shm after the run", shm_after.first <= shm_before.first,
           std::to_string(shm_before.first) + " -> " + std::to_string(shm_after.first) + " files");
    std::snprintf(buf, sizeof buf, "%.3f %%", missed_pct);
    target("missed deadlines < 1 %", missed_pct < 1.0, buf);
    target("no reliable sample lost", reliable_lost == 0 && dropped == 0, std::to_string(reliable_lost) + " lost, " + std::to_string(dropped) + " dropped");
    target("the run ended well", exit_code == 0 && summary.is_object() && summary.value("ok", false), "exit " + std::to_string(exit_code));
    return ok ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "bench_soak", kHelp, run); }
