// One scenario, one run, three hosts: cpm lab run on the central host (a network namespace with
// its own sshd, as are the car hosts) starts each car's simulator, bridge and fsm_node on the
// car's own host over ssh, records centrally, and leaves nothing running anywhere.
#include <cpm/HistoryClient.hpp>
#include <cpm/Security.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm_test/Gaps.hpp>
#include <cpm_test/Hosts.hpp>
#include <cpm_test/Isolation.hpp>
#include <cpm_test/Process.hpp>
#include <cpm_test/TempDir.hpp>
#include <cpm_test/SourceDir.hpp>

#include <VehicleState.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <sys/stat.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <thread>

using namespace std::chrono_literals;
using cpm_test::built_program;

namespace {

using cpm_test::command_line;
using cpm_test::cpm_prefix;

const std::string kRoot = cpm_test::source_dir();

/// The pids of cpm's programs (not sshd) in a host's namespace.
std::vector<std::string> programs_on(const cpm_test::NamespaceHosts& hosts, size_t host)
{
    std::vector<std::string> out;
    for (int pid : hosts.pids(host)) {
        const std::string cmd = command_line(pid);
        if (cmd.rfind(cpm_prefix(), 0) == 0) out.push_back(cmd.substr(0, cmd.find(' ')));
    }
    return out;
}

/// The shared memory ports (Fast DDS's /dev/shm/fastrtps_port<N>) the processes on a host have
/// mapped: their own and those they deliver to.
std::set<std::string> shared_memory_ports_on(const cpm_test::NamespaceHosts& hosts, size_t host)
{
    std::set<std::string> out;
    for (int pid : hosts.pids(host)) {
        std::istringstream maps(cpm_test::file_text("/proc/" + std::to_string(pid) + "/maps"));
        for (std::string line; std::getline(maps, line);) {
            if (const auto at = line.find("/dev/shm/fastrtps_port"); at != std::string::npos) out.insert(line.substr(at));
        }
    }
    return out;
}

/// The ssh connections a host's sshd serves now (a process "sshd: USER@..." each).
size_t ssh_connections_to(const cpm_test::NamespaceHosts& hosts, size_t host)
{
    size_t n = 0;
    for (int pid : hosts.pids(host)) n += command_line(pid).rfind("sshd: root@", 0) == 0;
    return n;
}

/// ssh's processes on a host (a run's shared connections are "ssh: <path> [mux]").
std::vector<std::string> ssh_clients_on(const cpm_test::NamespaceHosts& hosts, size_t host)
{
    std::vector<std::string> out;
    for (int pid : hosts.pids(host)) {
        const std::string cmd = command_line(pid);
        if (cmd.rfind("ssh", 0) == 0 || cmd.rfind("/usr/bin/ssh ", 0) == 0) out.push_back(cmd);
    }
    return out;
}

/// Whether a real-time `cpm lab run` said its lab time started (every car has sent its first
/// state: the cars over ssh are up) within a minute.
bool lab_time_started(cpm_test::Process& run)
{
    // Not past the run's end: a run refused at its start says so at once.
    return cpm_test::wait_until([&] { return run.errors().find("lab time starts") != std::string::npos || run.wait(0ms) >= 0; }, 60s) &&
           run.errors().find("lab time starts") != std::string::npos;
}

/// What a car's simulator and bridge warned of in the run's folder `out`, for a failure's message.
std::string car_warnings(const std::string& out, int car)
{
    const std::string id = std::to_string(car);
    return "the car's warnings (sim_" + id + ", bridge_" + id + "):\n" + cpm_test::warnings_in(out + "/sim_" + id + ".log") +
           cpm_test::warnings_in(out + "/bridge_" + id + ".log");
}

bool runs(const std::vector<std::string>& programs, const std::string& name)
{
    return std::any_of(programs.begin(), programs.end(), [&](const std::string& p) { return std::filesystem::path(p).filename() == name; });
}

class LabAcrossHosts : public ::testing::Test
{
protected:
    void SetUp() override
    {
        cpm_test::test_domain_id();
        hosts_.emplace(std::vector<std::string>{"central", "car_a", "car_b"});
        if (!hosts_->why_not().empty()) GTEST_SKIP() << "no namespace hosts: " << hosts_->why_not() << "; not run";
    }
    cpm_test::NamespaceHosts& hosts() { return *hosts_; }
    /// A scenario with one car on each car host, the history and this run on the central host;
    /// `car_a_extra`, `car_b_extra`: more of car 5's keys, of car 6's. Car 5 follows the corridor's
    /// walls; with a camera in `car_a_extra` it looks for the gates (a machine that needs one).
    std::string scenario(const std::string& extra = "", const std::string& car_a_extra = "", const std::string& car_b_extra = "")
    {
        const std::string car_a_fsm = ", fsm: " + kRoot + "/scenarios/fsm/" + (car_a_extra.find("camera:") != std::string::npos ? "gates.json" : "corridor.json");
        std::string hosts_yaml = "hosts:\n  central: {address: " + hosts().address(0) + "}\n";
        for (size_t i = 1; i < 3; ++i) {
            hosts_yaml += "  " + std::string(i == 1 ? "car_a" : "car_b") + ": {address: " + hosts().address(i) + ", ssh: " +
                          (i == 1 ? "car_a" : "car_b") + ", cpm: " + cpm_prefix() + "}\n";
        }
        return dir.write("two_cars.yaml", "name: across\ntime: real\nduration: 6s\nworld: " + kRoot + "/scenarios/maps/gates.json\n" +
                                              hosts_yaml + "ssh_config: " + hosts().ssh_config() + "\n" + extra +
                                              "history: {host: central}\n"
                                              "vehicles:\n"
                                              "  - {id: 5, host: car_a, realtime: true, start: [0.0, 0.0, 0.3]" + car_a_fsm + car_a_extra + "}\n"
                                              "  - {id: 6, host: car_b, realtime: true, start: [0.0, 0.6, 0.3]" + car_b_extra + "}\n");
    }
    cpm_test::TempDir dir;

private:
    std::optional<cpm_test::NamespaceHosts> hosts_;
};

}  // namespace

TEST_F(LabAcrossHosts, EachCarRunsOnItsHostTheRecordingIsCentralAndNothingIsLeftAnywhere)
{
    const std::string file = scenario();
    const std::string out = dir.file("across-" + std::to_string(::getpid()));
    const uint64_t central_received_before = hosts().received_bytes(0);
    // A car's programs start over ssh a few seconds into the run (2.5-3.5 s here, more on a busy
    // host): the run's 6 s of lab time start once every car has sent its first state.
    cpm_test::Process run(hosts().in(0, {built_program("cpm"), "lab", "run", file, "--out", out, "--monitor", "off"}));
    // While it runs (its lab time started: every car's programs are up): each car's programs on
    // its own host, none of them on the others.
    ASSERT_TRUE(lab_time_started(run)) << run.output() << run.errors();
    bool seen = false;
    cpm_test::wait_until([&] {
        const auto a = programs_on(hosts(), 1), b = programs_on(hosts(), 2), central = programs_on(hosts(), 0);
        seen = runs(a, "firmware_sim") && runs(a, "vehicle_bridge") && runs(a, "fsm_node") && runs(b, "firmware_sim") &&
               runs(b, "vehicle_bridge") && !runs(central, "firmware_sim") && runs(central, "cpm_history");
        return seen;
    }, 30s, 200ms);
    // What a car's programs read comes from the run's folder on its host (copied there).
    std::string fsm_command;
    for (int pid : hosts().pids(1)) {
        if (command_line(pid).find("/bin/fsm_node ") != std::string::npos) fsm_command = command_line(pid);
    }
    // Shared memory within each host, never between two: no host maps another's ports.
    const auto central_ports = shared_memory_ports_on(hosts(), 0), a_ports = shared_memory_ports_on(hosts(), 1),
               b_ports = shared_memory_ports_on(hosts(), 2);
    EXPECT_FALSE(central_ports.empty() || a_ports.empty() || b_ports.empty()) << "shared memory within a host is on";
    for (const auto& port : a_ports) EXPECT_FALSE(central_ports.count(port) || b_ports.count(port)) << port << " of car_a mapped on another host";
    for (const auto& port : b_ports) EXPECT_FALSE(central_ports.count(port)) << port << " of car_b mapped on the central host";
    // Every command the run sends a car host shares one ssh connection (one key exchange).
    for (size_t h : {1u, 2u}) EXPECT_EQ(ssh_connections_to(hosts(), h), 1u) << "host " << h;
    EXPECT_NE(fsm_command.find("--fsm /tmp/cpm-runs/across-" + std::to_string(::getpid()) + "/"), std::string::npos) << fsm_command;
    EXPECT_TRUE(seen) << "car_a runs " << ::testing::PrintToString(programs_on(hosts(), 1)) << ", car_b "
                      << ::testing::PrintToString(programs_on(hosts(), 2)) << ", central " << ::testing::PrintToString(programs_on(hosts(), 0));
    ASSERT_EQ(run.wait(90s), 0) << run.output() << run.errors();
    EXPECT_NE(run.errors().find(" s after the processes were started (every car has sent its first state)"), std::string::npos) << run.errors();

    std::ifstream in(out + "/summary.json");
    const auto summary = nlohmann::json::parse(in);
    EXPECT_TRUE(summary["ok"].get<bool>()) << summary.dump(2);
    ASSERT_EQ(summary["hosts"].size(), 3u) << summary.dump(2);
    for (const auto& h : summary["hosts"]) {
        if (h["name"] == "central") continue;
        EXPECT_GT(h["rtt_ns"].get<int64_t>(), 0) << h.dump();
        EXPECT_LT(std::llabs(h["clock_offset_ns"].get<int64_t>()), 2'000'000) << h.dump();  // one machine: one clock
    }
    // The report shows each host with its clock offset.
    const std::string report = cpm_test::file_text(out + "/report.html");
    EXPECT_NE(report.find("<h2>Hosts</h2>"), std::string::npos) << "no hosts in the report";
    EXPECT_NE(report.find("<tr><td>car_a</td><td>" + hosts().address(1) + "</td>"), std::string::npos) << report;
    // The central recording holds both cars' states at their 50 Hz from their own hosts.
    auto recording = cpm::HistoryClient::open_recording(out + "/recording.db");
    size_t state_bytes = 0;  // the cars' states the central host recorded, as serialized
    for (int car : {5, 6}) {
        const auto states = recording.range_of<VehicleState>("vehicleState", car, 0, UINT64_MAX, cpm::HistoryBy::commit, 100000);
        ASSERT_GE(states.samples.size(), 2u) << "car " << car;
        for (const auto& s : states.samples) state_bytes += VehicleState::getCdrSerializedSize(s.sample);
        // At 50 Hz with nothing lost, over the whole lab time (it began with the cars' first states).
        const auto stamp = [](const auto& r) { return r.data_ns; };
        const double span_s = double(stamp(states.samples.back()) - stamp(states.samples.front())) * 1e-9;
        EXPECT_GE(span_s, summary["lab_time_s"].get<double>() - 0.5) << "car " << car << "'s states span less than the run";
        EXPECT_NEAR(summary["lab_time_s"].get<double>(), 6.0, 0.1) << summary.dump(2);
        // A failure says where the states went missing, and what the recorder knew it lost.
        std::vector<uint64_t> stamps;
        for (const auto& s : states.samples) stamps.push_back(stamp(s));
        EXPECT_GE(double(states.samples.size()), 0.98 * span_s * 50)
            << "car " << car << ": " << states.samples.size() << " states in " << span_s << " s; gaps over 30 ms: "
            << cpm_test::gaps_over(stamps, stamp(states.samples.front()), 30'000'000) << "; the recording's account: "
            << summary["recording"].dump() << "\n" << car_warnings(out, car);
    }
    // So they came over the wire: the central host's link received at least their bytes.
    const uint64_t central_received = hosts().received_bytes(0) - central_received_before;
    EXPECT_GE(central_received, state_bytes) << "the central host's link received " << central_received << " bytes; the cars' states are " << state_bytes;
    EXPECT_FALSE(std::filesystem::exists("/tmp/cpm-runs/across-" + std::to_string(::getpid()))) << "the run's folder on the car hosts stays";
    // Nothing of the run is left on any host, no ssh connection either.
    EXPECT_TRUE(ssh_clients_on(hosts(), 0).empty()) << ::testing::PrintToString(ssh_clients_on(hosts(), 0));
    for (size_t h = 0; h < 3; ++h) {
        EXPECT_TRUE(cpm_test::wait_until([&] { return programs_on(hosts(), h).empty(); }, 10s))
            << "left on host " << h << ": " << ::testing::PrintToString(programs_on(hosts(), h));
    }
}

TEST_F(LabAcrossHosts, InSimulatedTimeTheClockWaitsForTheCarsOnTheirHostsAndEveryTickIsRecorded)
{
    // Car 5 looks for gates with its camera: the camera, its marker finder and the state
    // machine on car_a step with the lab clock too.
    // Car 6's machine includes another file (FSMState file:), which goes to car_b beside it.
    std::filesystem::create_directories(dir.path / "fsm" / "parts");
    dir.write("fsm/parts/corridor.json", cpm_test::file_text(kRoot + "/scenarios/fsm/corridor.json"));
    dir.write("fsm/car6.json", R"({"root": 0, "tick_period": 0.02, "states": [{"id": 0, "type": "FSMState", "file": "parts/corridor.json", "final": true}], "transitions": []})");
    const std::string file = scenario("record: {topics: [\"*\"], exclude: [cameraFrame]}\n", ", camera: " + kRoot + "/scenarios/cameras/sim_640x480.yaml",
                                      ", fsm: " + dir.file("fsm/car6.json"));
    const std::string out = dir.file("simulated");
    cpm_test::Process run(hosts().in(0, {built_program("cpm"), "lab", "run", file, "--out", out, "--monitor", "off", "--time", "simulated", "--duration", "10s"}));
    ASSERT_EQ(run.wait(120s), 0) << run.output() << run.errors() << cpm_test::file_text(out + "/fsm_5.log") << cpm_test::file_text(out + "/fsm_6.log");
    std::ifstream in(out + "/summary.json");
    const auto summary = nlohmann::json::parse(in);
    EXPECT_TRUE(summary["ok"].get<bool>()) << summary.dump(2);
    EXPECT_NEAR(summary["lab_time_s"].get<double>(), 10.0, 0.05) << summary.dump(2);
    // Lab time waits for the slowest node, wherever it runs: a car on another host misses no tick.
    auto recording = cpm::HistoryClient::open_recording(out + "/recording.db");
    for (int car : {5, 6}) {
        const auto states = recording.range_of<VehicleState>("vehicleState", car, 0, UINT64_MAX, cpm::HistoryBy::data, 100000);
        ASSERT_GE(states.samples.size(), 2u) << "car " << car;
        const uint64_t span_ns = states.samples.back().data_ns - states.samples.front().data_ns;
        // What a failure needs to be told apart: a late first state or an early last one, what
        // the recording says it lost, and what the car's programs warned of.
        const auto account = [&] {
            return "car " + std::to_string(car) + ": states from lab time " + std::to_string(states.samples.front().data_ns) + " to " +
                   std::to_string(states.samples.back().data_ns) + " ns; the recording's account: " + summary["recording"].dump() + "\n" +
                   car_warnings(out, car);
        };
        EXPECT_GE(span_ns, 9'000'000'000u) << account();
        EXPECT_EQ(states.samples.size(), span_ns / 20'000'000 + 1) << account() << "\none state per 20 ms tick of lab time";
    }
    // Car 6 on car_b ran the machine its file included (its wall follower drove it; the outer
    // machine alone has nothing that moves a car).
    double fastest = 0;
    for (const auto& s : recording.range_of<VehicleState>("vehicleState", 6, 0, UINT64_MAX, cpm::HistoryBy::data, 100000).samples)
        fastest = std::max(fastest, s.sample.speed());
    EXPECT_GT(fastest, 0.2) << "car 6 never drove";
    for (size_t h = 0; h < 3; ++h) EXPECT_TRUE(cpm_test::wait_until([&] { return programs_on(hosts(), h).empty(); }, 10s)) << "left on host " << h;
}

TEST_F(LabAcrossHosts, ASecuredLabGivesEachHostItsOwnNodesAndNeverACaKey)
{
    const std::string lab = dir.file("lab-sec");
    cpm_test::Process init({built_program("cpm"), "security", "init", lab, "--days", "30"});
    ASSERT_EQ(init.wait(60s), 0) << init.errors();
    const std::string name = "secured-" + std::to_string(::getpid()), out = dir.file(name), there = "/tmp/cpm-runs/" + name;
    cpm_test::Process run(hosts().in(0, {built_program("cpm"), "lab", "run", scenario("security: " + lab + "\n"), "--out", out, "--monitor", "off",
                                         "--duration", "10s"}));
    // While the cars run: each process on a car host runs as its own node from the run's folder
    // there, which holds the nodes of the car hosts' processes and no key of a CA.
    std::map<std::string, std::string> node_of;  // a car host's process's --security -> the program
    ASSERT_TRUE(cpm_test::wait_until([&] {
        for (size_t h : {1u, 2u}) {
            for (int pid : hosts().pids(h)) {
                const std::string cmd = command_line(pid);
                const auto at = cmd.find(" --security ");
                if (cmd.rfind(cpm_prefix() + "/bin/", 0) == 0 && cmd.find("/bin/cpm ") == std::string::npos && at != std::string::npos)
                    node_of[cmd.substr(at + 12, cmd.find(' ', at + 12) - at - 12)] = cmd.substr(0, cmd.find(' '));
            }
        }
        return node_of.size() >= 5;  // firmware_sim and vehicle_bridge of both cars, car 5's fsm_node
    }, 60s)) << run.errors() << ::testing::PrintToString(node_of);
    std::set<std::string> files_there;
    for (const auto& e : std::filesystem::recursive_directory_iterator(there + "/security")) {
        if (e.is_regular_file()) files_there.insert(std::filesystem::relative(e.path(), there + "/security").string());
    }
    for (const auto& [node, program] : node_of) {
        EXPECT_EQ(node.rfind(there + "/security/" + name + "-", 0), 0u) << program << " runs as " << node;
        EXPECT_EQ(cpm_test::file_text(node + "/cert.pem"), cpm_test::file_text(lab + "/nodes/" + std::filesystem::path(node).filename().string() + "/cert.pem"));
        struct stat st{};
        ASSERT_EQ(::stat((node + "/key.pem").c_str(), &st), 0) << node;
        EXPECT_EQ(st.st_mode & 077, 0u) << node << "/key.pem is readable by others";
    }
    for (const auto& f : files_there) {
        EXPECT_EQ(f.find("ca.key"), std::string::npos) << "a CA's key on a car host: " << f;
        EXPECT_EQ(f.find("cpm_history"), std::string::npos) << "the central host's node on a car host: " << f;
    }
    EXPECT_EQ(files_there.size(), node_of.size() * std::size(cpm::security::kNodeFileNames)) << ::testing::PrintToString(files_there);
    ASSERT_EQ(run.wait(90s), 0) << run.output() << run.errors();
    std::ifstream in(out + "/summary.json");
    const auto summary = nlohmann::json::parse(in);
    EXPECT_TRUE(summary["ok"].get<bool>()) << summary.dump(2);
    // The secured history on the central host recorded both cars from their hosts (how many
    // depends on how long the secured handshakes took on this machine: the rates are the other tests').
    auto recording = cpm::HistoryClient::open_recording(out + "/recording.db");
    for (int car : {5, 6}) EXPECT_GT(recording.range_of<VehicleState>("vehicleState", car, 0, UINT64_MAX, cpm::HistoryBy::commit, 100000).samples.size(), 0u) << car;
    EXPECT_FALSE(std::filesystem::exists(there)) << "the run's folder on the car hosts stays";
}

TEST_F(LabAcrossHosts, WithADiscoveryServerEveryProcessFindsTheOthersThroughIt)
{
    const std::string out = dir.file("server");
    cpm_test::Process run(hosts().in(0, {built_program("cpm"), "lab", "run", scenario("discovery: server\ndiscovery_server: central\nrecord: {topics: [\"*\"], exclude: [cameraFrame]}\n",
                                                                               ", camera: " + kRoot + "/scenarios/cameras/sim_640x480.yaml"),
                                         "--out", out,
                                         "--monitor", "off", "--time", "simulated", "--duration", "5s"}));
    auto server_runs = [&] {
        for (int pid : hosts().pids(0)) {
            if (command_line(pid).rfind("/usr/bin/fast-discovery-server -i 0 -l " + hosts().address(0) + " -p 11811", 0) == 0) return true;
        }
        return false;
    };
    ASSERT_EQ(run.wait(120s), 0) << run.output() << run.errors();
    std::ifstream in(out + "/summary.json");
    const auto summary = nlohmann::json::parse(in);
    // What ran where, from the run's own account (a poll of the hosts' processes missed the
    // short run on a loaded machine): the server on the central host, car_a's bridge told to use it.
    std::vector<std::string> server, bridge;
    for (const auto& p : summary["processes"]) {
        const auto argv = p["argv"].get<std::vector<std::string>>();
        if (p["host"] == "central" && argv.at(0) == "/usr/bin/fast-discovery-server") server = argv;
        if (p["host"] == "car_a" && argv.at(0).ends_with("/bin/vehicle_bridge")) bridge = argv;
    }
    EXPECT_EQ(server, (std::vector<std::string>{"/usr/bin/fast-discovery-server", "-i", "0", "-l", hosts().address(0), "-p", "11811"}))
        << summary.dump(2);
    const auto flag = std::find(bridge.begin(), bridge.end(), "--dds_discovery_server");
    ASSERT_TRUE(flag != bridge.end() && flag + 1 != bridge.end()) << "car_a's bridge with --dds_discovery_server ADDRESS: " << summary.dump(2);
    EXPECT_EQ(*(flag + 1), hosts().address(0) + ":11811") << summary.dump(2);
    EXPECT_EQ(std::find(bridge.begin(), bridge.end(), "--dds_initial_peer"), bridge.end()) << ::testing::PrintToString(bridge);
    EXPECT_TRUE(summary["ok"].get<bool>()) << summary.dump(2);
    auto recording = cpm::HistoryClient::open_recording(out + "/recording.db");
    for (int car : {5, 6}) {
        const auto states = recording.range_of<VehicleState>("vehicleState", car, 0, UINT64_MAX, cpm::HistoryBy::data, 100000);
        EXPECT_GE(states.samples.size(), 200u) << "car " << car << ": 5 s of lab time at 50 Hz";
    }
    EXPECT_TRUE(cpm_test::wait_until([&] { return !server_runs(); }, 10s)) << "the discovery server is left running";
}

TEST_F(LabAcrossHosts, AHostWithoutSshIsRefusedBeforeAnythingStarts)
{
    hosts().stop_sshd(2);
    cpm_test::Process run(hosts().in(0, {built_program("cpm"), "lab", "run", scenario(), "--out", dir.file("run"), "--monitor", "off"}));
    EXPECT_EQ(run.wait(60s), 1) << run.output() << run.errors();
    EXPECT_NE(run.errors().find("hosts.car_b: cannot run " + cpm_prefix() + "/bin/cpm there with ssh car_b (ssh exited with code 255;"),
              std::string::npos) << run.errors();
    for (size_t h = 0; h < 3; ++h) EXPECT_TRUE(programs_on(hosts(), h).empty()) << "started on host " << h << " though the run was refused";

}

TEST_F(LabAcrossHosts, AHostWhoseClockIsOffIsRefusedNamingTheOffset)
{
    // car_a's clock 50 ms ahead (libfaketime under its sshd), the bound 2 ms.
    ASSERT_TRUE(hosts().offset_clock(1, "+0.05")) << "libfaketime (Debian's libfaketime) is needed";
    cpm_test::Process run(hosts().in(0, {built_program("cpm"), "lab", "run", scenario(), "--out", dir.file("run"), "--monitor", "off"}));
    EXPECT_EQ(run.wait(60s), 1) << run.output() << run.errors();
    const std::string said = run.errors();
    const auto at = said.find("hosts.car_a: its clock is ");
    ASSERT_NE(at, std::string::npos) << said;
    const double offset_ms = std::atof(said.c_str() + at + std::strlen("hosts.car_a: its clock is "));
    EXPECT_NEAR(offset_ms, 50.0, 5.0) << said;
    EXPECT_NE(said.find("more than max_clock_offset 2.000 ms: synchronise the hosts' clocks (chrony or NTP)"), std::string::npos) << said;
    EXPECT_EQ(said.find("hosts.car_b"), std::string::npos) << "car_b's clock is right: " << said;
    for (size_t h = 0; h < 3; ++h) EXPECT_TRUE(programs_on(hosts(), h).empty()) << "started on host " << h << " though the run was refused";
}

TEST_F(LabAcrossHosts, ACarHostLostMidRunIsNamedAndTheOtherCarDrivesOnToTheEnd)
{
    const std::string out = dir.file("lost-" + std::to_string(::getpid()));
    cpm_test::Process run(hosts().in(0, {built_program("cpm"), "lab", "run", scenario(), "--out", out, "--monitor", "off", "--duration", "12s"}));
    // Mid-run: 2 s after the lab time started (every car's first state; on a loaded machine a
    // cut 2 s after car_b's bridge came up came before its first state, and the clock never started).
    ASSERT_TRUE(lab_time_started(run)) << run.output() << run.errors();
    ASSERT_TRUE(runs(programs_on(hosts(), 2), "vehicle_bridge")) << run.errors();
    std::this_thread::sleep_for(2s);
    const uint64_t cut_ns = cpm::get_time_ns();
    ASSERT_TRUE(hosts().cut(2));  // car_b's cable pulled
    EXPECT_EQ(run.wait(90s), 1) << "a run that lost a host is not ok\n" << run.output() << run.errors();
    EXPECT_NE((run.output() + run.errors()).find("sim_6 lost with host car_b (ssh ended: the host was not reached or the connection broke); the run goes on without it"), std::string::npos) << run.output() << run.errors();

    std::ifstream in(out + "/summary.json");
    const auto summary = nlohmann::json::parse(in);
    EXPECT_EQ(summary["error"], "") << "the run went on: " << summary.dump(2);
    EXPECT_NEAR(summary["lab_time_s"].get<double>(), 12.0, 0.5) << summary.dump(2);
    for (const auto& h : summary["hosts"]) EXPECT_EQ(h["lost"].get<bool>(), h["name"] == "car_b") << h.dump();
    for (const auto& p : summary["processes"]) {
        if (p["host"] == "car_b") {
            EXPECT_EQ(p["end"], "lost with host car_b") << p.dump();
        }
    }
    // car_a drove on after the cut; car_b's states stopped with it.
    auto recording = cpm::HistoryClient::open_recording(out + "/recording.db");
    const auto a = recording.range_of<VehicleState>("vehicleState", 5, cut_ns + 1'000'000'000, UINT64_MAX, cpm::HistoryBy::commit, 100000);
    const auto b = recording.range_of<VehicleState>("vehicleState", 6, cut_ns + 1'000'000'000, UINT64_MAX, cpm::HistoryBy::commit, 100000);
    EXPECT_GE(a.samples.size(), 200u) << "car_a's states after the cut";
    EXPECT_EQ(b.samples.size(), 0u) << "car_b's states after its host was cut off";
    // Cut off from the run, car_b stops the run's processes by itself (its link still down).
    EXPECT_TRUE(cpm_test::wait_until([&] { return programs_on(hosts(), 2).empty(); }, cpm::kRemoteLease + 10s))
        << "left on the lost host: " << ::testing::PrintToString(programs_on(hosts(), 2));
    for (size_t h = 0; h < 2; ++h) EXPECT_TRUE(programs_on(hosts(), h).empty()) << "left on host " << h;
}

TEST_F(LabAcrossHosts, ACarHostLostJustBeforeTheEndIsNamedThoughSshNoticesItOnlyWhileTheRunStops)
{
    // The cut comes about 1.5 s before the run's end; ssh notices it (about 3 s) while the run
    // stops its processes: the host is lost all the same, not a process that "exited with code 255".
    const std::string out = dir.file("late-" + std::to_string(::getpid()));
    cpm_test::Process run(hosts().in(0, {built_program("cpm"), "lab", "run", scenario(), "--out", out, "--monitor", "off", "--duration", "6s"}));
    // The run's 6 s count from every car's first state (over ssh seconds after the start).
    ASSERT_TRUE(lab_time_started(run)) << run.output() << run.errors();
    std::this_thread::sleep_for(4500ms);
    ASSERT_TRUE(hosts().cut(2));
    EXPECT_EQ(run.wait(90s), 1) << "a run that lost a host is not ok\n" << run.output() << run.errors();
    EXPECT_NE((run.output() + run.errors()).find("sim_6 lost with host car_b (ssh ended: the host was not reached or the connection broke) while the run stopped"),
              std::string::npos) << run.output() << run.errors();
    std::ifstream in(out + "/summary.json");
    const auto summary = nlohmann::json::parse(in);
    EXPECT_EQ(summary["error"], "") << summary.dump(2);
    for (const auto& h : summary["hosts"]) EXPECT_EQ(h["lost"].get<bool>(), h["name"] == "car_b") << h.dump();
    for (const auto& p : summary["processes"]) {
        EXPECT_EQ(p["failed"].get<bool>(), p["host"] == "car_b") << p.dump();
        if (p["host"] == "car_b") {
            EXPECT_EQ(p["end"], "lost with host car_b") << p.dump();
        }
    }
    EXPECT_TRUE(cpm_test::wait_until([&] { return programs_on(hosts(), 2).empty(); }, cpm::kRemoteLease + 10s))
        << "left on the lost host: " << ::testing::PrintToString(programs_on(hosts(), 2));
}

TEST_F(LabAcrossHosts, APlannerHostLostMidRunBrakesTheCarsOnTheirOwnHostAndEndsTheRunNamingIt)
{
    // Two cars on car_a, routed by central_routing on car_b: car_b carries more than cars.
    const std::string file = dir.write("routed.yaml", "name: routed\ntime: real\nduration: 30s\nlanes: " + kRoot + "/scenarios/lanes/intersection.json\n"
                                       "hosts:\n  central: {address: " + hosts().address(0) + "}\n"
                                       "  car_a: {address: " + hosts().address(1) + ", ssh: car_a, cpm: " + cpm_prefix() + "}\n"
                                       "  car_b: {address: " + hosts().address(2) + ", ssh: car_b, cpm: " + cpm_prefix() + "}\n"
                                       "ssh_config: " + hosts().ssh_config() + "\n"
                                       "history: {host: central}\n"
                                       "routing: {enabled: true, seed: 1, period: 400ms, host: car_b}\n"
                                       "vehicles:\n  - {id: 1, host: car_a}\n  - {id: 2, host: car_a}\n");
    const std::string out = dir.file("routed-" + std::to_string(::getpid()));
    cpm_test::Process run(hosts().in(0, {built_program("cpm"), "lab", "run", file, "--out", out, "--monitor", "off"}));
    // Mid-run: once the lab time started (routing starts with it), polled from the run's own
    // output, not from car_b's process list (a fresh build's first tests missed it within 30 s).
    ASSERT_TRUE(lab_time_started(run)) << run.output() << run.errors();
    ASSERT_TRUE(runs(programs_on(hosts(), 2), "central_routing")) << run.errors();
    std::this_thread::sleep_for(5s);  // the cars drive on its trajectories
    const uint64_t cut_ns = cpm::get_time_ns();
    ASSERT_TRUE(hosts().cut(2));  // the planner's cable pulled
    EXPECT_EQ(run.wait(60s), 1) << run.output() << run.errors();
    EXPECT_NE(run.errors().find("central_routing lost with host car_b"), std::string::npos) << run.output() << run.errors();

    std::ifstream in(out + "/summary.json");
    const auto summary = nlohmann::json::parse(in);
    EXPECT_NE(summary["error"].get<std::string>().find("central_routing lost with host car_b"), std::string::npos) << summary.dump(2);
    EXPECT_LT(summary["lab_time_s"].get<double>(), 25.0) << "the run ended when it lost its planner, not at its duration";
    for (const auto& h : summary["hosts"]) EXPECT_EQ(h["lost"].get<bool>(), h["name"] == "car_b") << h.dump();
    // On car_a, still reached, each car drove before the cut and stood by its bridge's watchdog
    // (the newest trajectory goes stale 1 s after it was made) before the run ended.
    auto recording = cpm::HistoryClient::open_recording(out + "/recording.db");
    for (int car : {1, 2}) {
        const auto before = recording.range_of<VehicleState>("vehicleState", car, cut_ns - 3'000'000'000, cut_ns, cpm::HistoryBy::data, 100000);
        const auto after = recording.range_of<VehicleState>("vehicleState", car, cut_ns, UINT64_MAX, cpm::HistoryBy::data, 100000);
        ASSERT_FALSE(before.samples.empty() || after.samples.empty()) << "car " << car;
        double fastest = 0;
        for (const auto& s : before.samples) fastest = std::max(fastest, std::abs(s.sample.speed()));
        EXPECT_GT(fastest, 0.2) << "car " << car << " drove before the cut";
        uint64_t stood_ns = 0;
        for (const auto& s : after.samples) {
            if (std::abs(s.sample.speed()) < 0.02) {
                stood_ns = s.data_ns;
                break;
            }
        }
        ASSERT_NE(stood_ns, 0u) << "car " << car << " still drove when the run ended: " << after.samples.back().sample.speed() << " m/s";
        EXPECT_LT(double(stood_ns - cut_ns) * 1e-9, 2.5) << "car " << car << " stood that long after the cut";
        std::printf("car %d stood %.2f s after its planner's host was cut off\n", car, double(stood_ns - cut_ns) * 1e-9);
    }
    for (size_t h = 0; h < 2; ++h) EXPECT_TRUE(cpm_test::wait_until([&] { return programs_on(hosts(), h).empty(); }, 10s)) << "left on host " << h;
    EXPECT_TRUE(cpm_test::wait_until([&] { return programs_on(hosts(), 2).empty(); }, cpm::kRemoteLease + 10s))
        << "left on the lost host: " << ::testing::PrintToString(programs_on(hosts(), 2));
}

TEST_F(LabAcrossHosts, ADomainInUseOnAnotherHostIsRefusedNamingTheHost)
{
    // A car simulator left running on car_b on the lab's domain, reachable from the central host.
    const std::string domain = std::to_string(cpm_test::test_domain_id());
    cpm_test::Process stranger(hosts().in(2, {built_program("firmware_sim"), "--vehicle_id", "9", "--dds_domain", domain, "--dds_interface",
                                              hosts().address(2), "--dds_initial_peer", hosts().address(0)}));
    ASSERT_TRUE(cpm_test::wait_until([&] { return stranger.output().find("device: ") != std::string::npos; }, 10s)) << stranger.errors();
    cpm_test::Process run(hosts().in(0, {built_program("cpm"), "lab", "run", scenario(), "--out", dir.file("run"), "--monitor", "off"}));
    EXPECT_EQ(run.wait(60s), 1) << run.output() << run.errors();
    EXPECT_NE(run.errors().find("domain " + domain + " is in use by 1 participant(s): firmware_sim on host car_b (" + hosts().address(2) + ")"),
              std::string::npos)
        << run.errors();
    for (size_t h = 0; h < 2; ++h) EXPECT_TRUE(programs_on(hosts(), h).empty()) << "started on host " << h << " though the run was refused";
    EXPECT_EQ(programs_on(hosts(), 2), std::vector<std::string>{built_program("firmware_sim")}) << "car_b runs the stranger alone";
}

TEST_F(LabAcrossHosts, AMonitorPortInUseOnItsHostIsRefusedNamingTheHost)
{
    std::optional<cpm_test::HeldTcpPort> taken;  // something on car_b listens on the port the monitor wants there
    {
        const cpm_test::NamespaceHosts::Inside on_car_b(hosts(), 2);
        taken.emplace();
    }
    const std::string port = std::to_string(taken->port());
    cpm_test::Process run(hosts().in(0, {built_program("cpm"), "lab", "run", scenario("monitor: {port: " + port + ", host: car_b}\n"), "--out",
                                         dir.file("run"), "--monitor", port}));
    EXPECT_EQ(run.wait(60s), 1) << run.output() << run.errors();
    EXPECT_NE(run.errors().find("two_cars.yaml: monitor: tcp:" + port + " cannot be taken on host car_b (Address already in use)"), std::string::npos)
        << run.errors();
    for (size_t h = 0; h < 3; ++h) EXPECT_TRUE(programs_on(hosts(), h).empty()) << "started on host " << h << " though the run was refused";
}

TEST_F(LabAcrossHosts, APythonControllerOnItsOwnHostDrivesTheCarsOfAnother)
{
    // Two cars on car_a; the platoon controller in Python with its middleware on car_b; the
    // history and this run on central.
    const std::string file = dir.write("platoon.yaml", "name: platoon\ntime: real\nduration: 8s\nlanes: " + kRoot + "/scenarios/lanes/ring.json\n"
                                       "hosts:\n  central: {address: " + hosts().address(0) + "}\n"
                                       "  car_a: {address: " + hosts().address(1) + ", ssh: car_a, cpm: " + cpm_prefix() + "}\n"
                                       "  car_b: {address: " + hosts().address(2) + ", ssh: car_b, cpm: " + cpm_prefix() + "}\n"
                                       "ssh_config: " + hosts().ssh_config() + "\n"
                                       "history: {host: central}\n"
                                       "vehicles:\n  - {id: 1, host: car_a}\n  - {id: 2, host: car_a}\n"
                                       "controllers:\n  - {program: " + kRoot + "/examples/python/platoon.py, name: platoon, host: car_b,\n"
                                       "     args: [\"--lanes\", \"" + kRoot + "/scenarios/lanes/ring.json\"], vehicles: [1, 2], period: 100ms}\n");
    const std::string out = dir.file("platoon-" + std::to_string(::getpid()));
    cpm_test::Process run(hosts().in(0, {built_program("cpm"), "lab", "run", file, "--out", out, "--monitor", "off"}));
    // Where the controller ran: the run's summary says (its processes' hosts, below).
    ASSERT_EQ(run.wait(120s), 0) << run.output() << run.errors() << cpm_test::file_text(out + "/hlc_platoon.log")
                                 << cpm_test::file_text(out + "/controller_platoon.log");
    std::ifstream in(out + "/summary.json");
    const auto summary = nlohmann::json::parse(in);
    const auto& c = summary["controllers"].at(0);
    EXPECT_GE(c["periods"].get<int>(), 70) << c.dump(2);
    // Real time across hosts: the first periods may come before the cars, and on a loaded
    // machine an answer now and then comes after its period ended; the middleware refuses it as
    // past (cpm_lab's rule) and counts it. Nothing else is refused; nine periods in ten answered.
    EXPECT_GE(c["answered"].get<int>(), c["periods"].get<int>() * 9 / 10) << c.dump(2);
    EXPECT_EQ(c["refused"], c["refused_by_reason"]["past_period"]) << "only late answers are refused: " << c.dump(2);
    EXPECT_LE(c["late_answers"].get<int>(), c["periods"].get<int>() / 10) << c.dump(2);
    std::printf("the controller on car_b: %s\n", c.dump().c_str());
    for (const char* car : {"1", "2"}) EXPECT_GT(summary["report"]["cars"][car]["driven_m"].get<double>(), 2.0) << "car " << car;
    int on_car_b = 0;
    for (const auto& p : summary["processes"]) {
        if (p["name"] == "controller_platoon" || p["name"] == "hlc_platoon") {
            EXPECT_EQ(p["host"], "car_b") << p.dump();
            on_car_b += p["host"] == "car_b";
        }
    }
    EXPECT_EQ(on_car_b, 2) << "the controller and its middleware ran on car_b: " << summary["processes"].dump(2);
    for (size_t h = 0; h < 3; ++h) EXPECT_TRUE(cpm_test::wait_until([&] { return programs_on(hosts(), h).empty(); }, 10s)) << "left on host " << h;
}
