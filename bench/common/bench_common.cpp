#include "bench_common.hpp"

#include <cpm/CommandLine.hpp>
#include <cpm/Error.hpp>
#include <cpm/Security.hpp>
#include <cpm/percentile.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <thread>

#include <fcntl.h>
#include <sched.h>
#include <sys/utsname.h>
#include <sys/wait.h>
#include <unistd.h>

extern char** environ;

namespace bench {

Stats stats_of(const std::vector<double>& v)
{
    return {.n = v.size(),
            .min = cpm::percentile(v, 0.0),
            .p50 = cpm::percentile(v, 0.50),
            .p90 = cpm::percentile(v, 0.90),
            .p99 = cpm::percentile(v, 0.99),
            .max = cpm::percentile(v, 1.0)};
}

void print_header(const std::string& what)
{
    std::printf("\n%s\n%-44s %8s %9s %9s %9s %9s %10s\n", what.c_str(), "case", "n", "min", "p50", "p90", "p99", "max");
}

void print_row(const std::string& label, const Stats& s)
{
    std::printf("%-44s %8zu %9.1f %9.1f %9.1f %9.1f %10.1f\n", label.c_str(), s.n, s.min, s.p50, s.p90, s.p99, s.max);
    std::fflush(stdout);
}

void print_ratio(const std::string& label, const Stats& ours, const Stats& reference)
{
    std::printf("%-44s p50 ratio %.2f   p99 ratio %.2f\n", label.c_str(), ours.p50 / reference.p50, ours.p99 / reference.p99);
    std::fflush(stdout);
}

void print_machine(const std::string& settings)
{
    utsname u{};
    uname(&u);
    std::string cpu = "?";
    std::ifstream cpuinfo("/proc/cpuinfo");
    for (std::string line; std::getline(cpuinfo, line);) {
        if (line.rfind("model name", 0) == 0) {
            cpu = line.substr(line.find(':') + 2);
            break;
        }
    }
    std::printf("machine: %s, %u cores, %s %s\nsettings: %s\n", cpu.c_str(), std::thread::hardware_concurrency(),
                u.sysname, u.release, settings.c_str());
}

cpm::ChildProcess spawn(const std::vector<std::string>& argv, const std::vector<std::string>& env, const std::string& out_path,
                        const std::string& err_path)
{
    return cpm::ChildProcess({.argv = argv, .env = env, .stdout_path = out_path, .stderr_path = err_path});
}

cpm::ChildProcess spawn_self(const std::vector<std::string>& args)
{
    std::vector<std::string> argv{cpm::sibling_executable(program_invocation_short_name)};
    argv.insert(argv.end(), args.begin(), args.end());
    return spawn(argv, {}, "");
}

int wait_child(cpm::ChildProcess& child, double timeout_s)
{
    auto end = child.wait(std::chrono::milliseconds(int64_t(timeout_s * 1000)));
    if (!end) end = child.stop(std::chrono::milliseconds(0));
    return end->signal == 0 ? end->code : -1;
}

BusyLoops::BusyLoops(unsigned count)
{
    for (unsigned c = 0; c < count; ++c) spinners_.push_back(spawn_self({"--role", "busy"}));
}

BusyLoops::~BusyLoops()
{
    for (auto& spinner : spinners_) {
        spinner.signal(SIGKILL);
        wait_child(spinner, 5);
    }
}

unsigned BusyLoops::every_core() { return std::max(1u, std::thread::hardware_concurrency()); }

void spin_if_asked(const std::string& role)
{
    if (role != "busy") return;
    for (;;) asm volatile("" ::: "memory");  // spin: keep a core busy
}

std::string cyclone_loopback_xml() { return CPM_CYCLONE_LOOPBACK_XML; }
std::string cyclone_loopback_env() { return "CYCLONEDDS_URI=file://" + cyclone_loopback_xml(); }

namespace {

int run_quietly(const std::string& command) { return std::system((command + " >/dev/null 2>&1").c_str()); }

std::unique_ptr<VethLink> g_link;
std::string g_interface, g_peer;

}  // namespace

VethLink::VethLink()
{
    const std::string tag = std::to_string(::getpid() % 100000);
    subnet_ = "10.232." + std::to_string(::getpid() % 250 + 1);
    ns_[0] = "cpmbench" + tag + "_a";
    ns_[1] = "cpmbench" + tag + "_b";
    if (::geteuid() != 0) throw cpm::Error("--link veth: making network namespaces needs root");
    const std::string a = "ip netns exec " + ns_[0] + " ", b = "ip netns exec " + ns_[1] + " ";
    const bool ok = run_quietly("ip netns add " + ns_[0]) == 0 && run_quietly("ip netns add " + ns_[1]) == 0 &&
                    run_quietly("ip link add cpmbv" + tag + " netns " + ns_[0] + " type veth peer name cpmbw" + tag + " netns " + ns_[1]) == 0 &&
                    run_quietly(a + "ip addr add " + address(0) + "/24 dev cpmbv" + tag) == 0 &&
                    run_quietly(b + "ip addr add " + address(1) + "/24 dev cpmbw" + tag) == 0 &&
                    run_quietly(a + "ip link set cpmbv" + tag + " up") == 0 && run_quietly(b + "ip link set cpmbw" + tag + " up") == 0 &&
                    run_quietly(a + "ip link set lo up") == 0 && run_quietly(b + "ip link set lo up") == 0;
    if (!ok) {
        remove();
        throw cpm::Error("--link veth: could not make two network namespaces joined by a veth pair (ip netns, ip link)");
    }
    // A participant made before the link carries leaves its address out: wait for both ends.
    const std::string both_up = a + "grep -qx up /sys/class/net/cpmbv" + tag + "/operstate && " + b + "grep -qx up /sys/class/net/cpmbw" + tag + "/operstate";
    for (int i = 0; i < 100 && run_quietly(both_up) != 0; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(50));
}

VethLink::~VethLink() { remove(); }

void VethLink::remove()
{
    for (const auto& ns : ns_) {
        if (ns.empty()) continue;
        // What is left there, but this program (which moved its main thread to side 0).
        run_quietly("ip netns pids " + ns + " | grep -vx " + std::to_string(::getpid()) + " | xargs -r kill -9");
        run_quietly("ip netns del " + ns);
    }
}

std::string VethLink::address(int side) const { return subnet_ + "." + std::to_string(side + 1); }

std::vector<std::string> VethLink::in(int side, std::vector<std::string> argv) const
{
    argv.insert(argv.begin(), {"/usr/sbin/ip", "netns", "exec", ns_[side]});
    return argv;
}

void VethLink::enter(int side) const
{
    const int fd = ::open(("/var/run/netns/" + ns_[side]).c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0 || ::setns(fd, CLONE_NEWNET) != 0) throw cpm::Error("--link veth: cannot enter namespace " + ns_[side]);
    ::close(fd);
}

std::string VethLink::cyclone_env(int side) const
{
    return "CYCLONEDDS_URI=<CycloneDDS><Domain id=\"any\"><General><Interfaces><NetworkInterface address=\"" + address(side) +
           "\"/></Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery><ParticipantIndex>auto</ParticipantIndex>"
           "<MaxAutoParticipantIndex>32</MaxAutoParticipantIndex><Peers><Peer address=\"" + address(1 - side) +
           "\"/></Peers></Discovery></Domain></CycloneDDS>";
}

const VethLink& use_veth_link()
{
    if (!g_link) {
        g_link = std::make_unique<VethLink>();
        g_link->enter(0);
        set_link_end(g_link->address(0), g_link->address(1));
        // Ended by a signal, the program would leave the namespaces behind: end it by exit.
        for (int sig : {SIGINT, SIGTERM}) std::signal(sig, [](int) { std::exit(130); });
    }
    return *g_link;
}

const VethLink* veth_link() { return g_link.get(); }

void set_link_end(const std::string& interface, const std::string& peer)
{
    g_interface = interface;
    g_peer = peer;
}

void apply_link_end(cpm::ParticipantOptions& o)
{
    if (g_interface.empty()) return;
    o.interfaces = {g_interface};
    o.initial_peers = {g_peer};
}

std::vector<std::string> far_side(std::vector<std::string> argv)
{
    if (g_link) argv.insert(argv.end(), {"--interface", g_link->address(1), "--peer", g_link->address(0)});
    return on_far_side(std::move(argv));
}

std::vector<std::string> on_far_side(std::vector<std::string> argv) { return g_link ? g_link->in(1, std::move(argv)) : argv; }

std::string cyclone_env_here() { return g_link ? g_link->cyclone_env(0) : cyclone_loopback_env(); }
std::string cyclone_env_far() { return g_link ? g_link->cyclone_env(1) : cyclone_loopback_env(); }

CyclonePinger::CyclonePinger(int domain, size_t size, const std::vector<std::string>& extra, const std::string& env)
    : ping_([&] {
          std::vector<std::string> argv{cpm::sibling_executable("cyclone_bench"), "ping", "--domain", std::to_string(domain), "--size",
                                        std::to_string(size), "--blocks"};
          argv.insert(argv.end(), extra.begin(), extra.end());
          return cpm::ProcessOptions{.argv = argv, .env = {env.empty() ? cyclone_env_here() : env}, .capture_stdout = true, .pipe_stdin = true};
      }())
{
}

CyclonePinger::~CyclonePinger()
{
    ping_.close_stdin();
    (void)ping_.wait(std::chrono::seconds(5));
}

bool CyclonePinger::block(int count, int warmup, std::vector<double>& one_way_us)
{
    if (!ok_ || !ping_.write_stdin(std::to_string(count) + " " + std::to_string(warmup) + "\n")) return ok_ = false;
    const size_t before = one_way_us.size();
    while (auto line = ping_.read_line()) {
        if (*line == "done") return ok_ = one_way_us.size() - before == size_t(count);
        one_way_us.push_back(std::atof(line->c_str()));
    }
    return ok_ = false;  // it ended: no pong, or a pong out of order (its stderr says which)
}

Rate cyclone_pub_sub(int domain, size_t size, int seconds, const std::vector<std::string>& pub_extra,
                            const std::vector<std::string>& sub_extra)
{
    const std::string sub_out = "/tmp/bench_cyclone_sub_" + std::to_string(getpid());
    const std::string pub_out = "/tmp/bench_cyclone_pub_" + std::to_string(getpid());
    const std::string exe = cpm::sibling_executable("cyclone_bench");
    std::vector<std::string> sub_argv{exe, "sub", "--domain", std::to_string(domain)};
    sub_argv.insert(sub_argv.end(), sub_extra.begin(), sub_extra.end());
    auto sub = spawn(on_far_side(sub_argv), {cyclone_env_far()}, sub_out);
    std::vector<std::string> pub_argv{exe, "pub", "--domain", std::to_string(domain), "--size", std::to_string(size), "--seconds",
                                      std::to_string(seconds)};
    pub_argv.insert(pub_argv.end(), pub_extra.begin(), pub_extra.end());
    auto pub = spawn(pub_argv, {cyclone_env_here()}, pub_out);
    const int pub_code = wait_child(pub, seconds + 60);
    const int sub_code = wait_child(sub, seconds + 90);
    Rate r;
    std::string word;
    int complete = 0;
    std::ifstream(sub_out) >> word >> r.received >> word >> r.lost >> word >> r.rate >> word >> complete;
    std::ifstream(pub_out) >> word >> r.written;
    std::remove(sub_out.c_str());
    std::remove(pub_out.c_str());
    r.ok = pub_code == 0 && sub_code == 0 && complete == 1 && r.received == r.written && r.lost == 0;
    return r;
}

bool data_sharing()
{
    const char* value = std::getenv("BENCH_DATA_SHARING");
    return value != nullptr && std::string(value) == "1";
}

SecuredLab::SecuredLab()
{
    char tmpl[] = "/tmp/cpm_bench_lab.XXXXXX";
    dir = std::string(::mkdtemp(tmpl)) + "/lab";
    cpm::security::init_lab(dir, 2);
    node = cpm::security::add_node(dir, "bench", {.publish = {"*"}, .subscribe = {"*"}, .days = 2});
}

SecuredLab::~SecuredLab()
{
    std::error_code ignored;
    std::filesystem::remove_all(std::filesystem::path(dir).parent_path(), ignored);
}

std::vector<long long> integer_list(const std::string& flag, const std::string& text, long long min, long long max)
{
    std::vector<long long> values;
    for (const auto& item : cpm::cli::split_list(flag, text)) values.push_back(cpm::cli::parse_integer(flag, item, min, max));
    return values;
}

void record(const Figure& f)
{
    const char* path = std::getenv("CPM_BENCH_JSON");
    if (!path || !*path) return;
    nlohmann::json j{{"bench", f.bench}, {"case", f.what}, {"unit", f.unit}, {"cpm", f.cpm}};
    j["peer"] = f.peer.empty() ? nlohmann::json(nullptr) : nlohmann::json(f.peer);
    j["peer_value"] = f.peer.empty() ? nlohmann::json(nullptr) : nlohmann::json(f.peer_value);
    j["ratio"] = f.peer.empty() || f.peer_value == 0 ? nlohmann::json(nullptr) : nlohmann::json(f.cpm / f.peer_value);
    j["target"] = f.target.empty() ? nlohmann::json(nullptr) : nlohmann::json(f.target);
    j["met"] = f.met < 0 ? nlohmann::json(nullptr) : nlohmann::json(f.met == 1);
    std::ofstream(path, std::ios::app) << j.dump() << '\n';
}

void record_latency(const std::string& bench, const std::string& what, const Stats& ours, const std::string& peer, const Stats& reference,
                    double target_p50)
{
    Figure p50{bench, what + " p50", "µs", ours.p50, peer, reference.p50};
    if (target_p50 > 0) {
        char t[64];
        std::snprintf(t, sizeof t, "p50 <= %.2fx peer", target_p50);
        p50.target = t;
        p50.met = ours.p50 <= target_p50 * reference.p50 ? 1 : 0;
    }
    record(p50);
    record({bench, what + " p99", "µs", ours.p99, peer, reference.p99});
}

}  // namespace bench
