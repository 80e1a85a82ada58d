// A network partition between two hosts, made on this one: two network namespaces joined by a
// veth pair (created here, as root), each side's processes with --dds_interface, their peer as
// --dds_initial_peer and shared memory off (/dev/shm is the same in every namespace). Car 5 (the
// firmware simulator and its bridge) and a history on side A; its state machine and another
// history on side B. Cutting the link brakes the car within a second; each history keeps what it
// saw; healing it lets the machine drive the car again within two seconds. And the README's
// secured lab across two machines, on the same two namespaces.
#include <cpm/get_time_ns.hpp>

#include <cpm_test/Hosts.hpp>
#include <cpm_test/Isolation.hpp>
#include <cpm_test/Process.hpp>
#include <cpm_test/TempDir.hpp>

#include "SimTrace.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <memory>
#include <optional>
#include <sstream>
#include <unistd.h>

namespace {

using namespace std::chrono_literals;
using cpm_test::built_program;
using cpm_test::Process;
using cpm_faults::kRoot;
using cpm_faults::first_mode_after;
using cpm_faults::pwm_after;

constexpr uint64_t kSecondNs = 1'000'000'000ull;

int shell(const std::string& command) { return std::system((command + " >/dev/null 2>&1").c_str()); }

/// iproute2's ip (Debian: /usr/sbin/ip, /sbin/ip on older ones); empty when not installed.
std::string ip_program()
{
    for (const char* path : {"/usr/sbin/ip", "/sbin/ip", "/usr/bin/ip", "/bin/ip"})
        if (::access(path, X_OK) == 0) return path;
    return "";
}

/// Two namespaces joined by a veth pair, addresses 10.199.N.1 (side A) and 10.199.N.2 (side B);
/// nothing else in either, so no packet can leave this host. Removed again by the destructor.
class TwoHosts
{
public:
    TwoHosts()
    {
        cpm_test::remove_stale_namespaces();
        const std::string tag = std::to_string(::getpid());
        subnet_ = "10.199." + std::to_string(::getpid() % 250 + 1);
        ns_ = {"cpmA" + tag, "cpmB" + tag};
        link_ = {"cpmva" + tag, "cpmvb" + tag};
        made_ = shell("ip netns add " + ns_[0]) == 0 && shell("ip netns add " + ns_[1]) == 0 &&
                shell("ip link add " + link_[0] + " netns " + ns_[0] + " type veth peer name " + link_[1] + " netns " + ns_[1]) == 0;
        for (int side = 0; made_ && side < 2; ++side) {
            made_ = shell(in(side) + "ip link set lo up") == 0 &&
                    shell(in(side) + "ip addr add " + address(side) + "/24 dev " + link_[side]) == 0 &&
                    shell(in(side) + "ip link set " + link_[side] + " up") == 0;
        }
        // Fast DDS binds only to interfaces that are up when a participant starts: wait for the
        // pair's carrier on both ends.
        made_ = made_ && cpm_test::wait_until([&] { return carrier(0) && carrier(1); }, std::chrono::seconds(5), std::chrono::milliseconds(20));
    }
    /// Whether a side's end of the pair is up with its carrier.
    bool carrier(int side) const { return shell(in(side) + "grep -qx up /sys/class/net/" + link_[side] + "/operstate") == 0; }
    ~TwoHosts()
    {
        shell("ip netns del " + ns_[0]);
        shell("ip netns del " + ns_[1]);  // the veth pair goes with them
    }
    bool made() const { return made_; }
    std::string address(int side) const { return subnet_ + (side == 0 ? ".1" : ".2"); }
    /// The command prefix that runs a program in a side's namespace.
    std::string in(int side) const { return "ip netns exec " + ns_[side] + " "; }
    /// A cpm program on a side: its own address, the other side as its peer, no shared memory.
    std::vector<std::string> program(int side, std::vector<std::string> argv) const
    {
        std::vector<std::string> out{ip_program(), "netns", "exec", ns_[side]};
        out.insert(out.end(), argv.begin(), argv.end());
        for (const std::string& flag : std::vector<std::string>{"--dds_interface", address(side), "--dds_initial_peer",
                                                                address(1 - side), "--dds_shared_memory", "off"})
            out.push_back(flag);
        return out;
    }
    bool cut() const { return shell(in(0) + "ip link set " + link_[0] + " down") == 0; }
    bool heal() const { return shell(in(0) + "ip link set " + link_[0] + " up") == 0; }

private:
    std::string subnet_;
    std::vector<std::string> ns_, link_;
    bool made_ = false;
};

/// How many vehicleState samples of car 5, made between t0 and t1, a side's history holds.
int held_states(const TwoHosts& hosts, int side, uint64_t t0, uint64_t t1)
{
    Process ask(hosts.program(side, {built_program("cpm"), "history", "range", "--topic", "vehicleState", "--key", "5", "--from",
                                     std::to_string(t0), "--to", std::to_string(t1), "--by", "data", "--json"}));
    const int exit_code = ask.wait(30s);
    // None held: not_found, or not_yet (nothing after the newest it holds, which may still come).
    if (exit_code == 1 && (ask.errors().find("not_found") != std::string::npos || ask.errors().find("not_yet") != std::string::npos))
        return 0;
    if (exit_code != 0) {
        std::printf("cpm history range on side %c: exit %d: %s\n", side == 0 ? 'A' : 'B', exit_code, ask.errors().c_str());
        return -1;
    }
    int lines = 0;
    std::istringstream in(ask.output());
    for (std::string line; std::getline(in, line);) lines += !line.empty();
    return lines;
}

/// Each test on its own pair of namespaces; skipped, saying why, where they cannot be made.
class Partition : public ::testing::Test
{
protected:
    void SetUp() override
    {
        if (::geteuid() != 0) GTEST_SKIP() << "making network namespaces needs root (ip netns); not run";
        if (ip_program().empty()) GTEST_SKIP() << "iproute2's ip is not installed; not run";
        hosts_.emplace();
        if (!hosts_->made()) GTEST_SKIP() << "could not make two network namespaces joined by a veth pair (ip netns, ip link); not run";
    }
    const TwoHosts& hosts() const { return *hosts_; }
    /// Every process of both sides: UDP only (/dev/shm is the same in every namespace).
    const std::vector<std::string> env{"CPM_SHARED_MEMORY=off"};

private:
    std::optional<TwoHosts> hosts_;
};

TEST_F(Partition, CuttingTheLinkBrakesTheCarEachHistoryKeepsWhatItSawAndHealingDrivesItAgain)
{
    const TwoHosts& hosts = this->hosts();

    Process history_a(hosts.program(0, {built_program("cpm_history"), "--window", "60s"}), env);
    Process history_b(hosts.program(1, {built_program("cpm_history"), "--window", "60s"}), env);
    const std::string link = "/tmp/cpm_partition_" + std::to_string(::getpid()) + ".tty";
    Process sim(hosts.program(0, {built_program("firmware_sim"), "--vehicle_id", "5", "--map", kRoot + "/scenarios/maps/corridor.json",
                                  "--start", "0,-0.01,0", "--link", link, "--trace-pwm"}),
                env);
    ASSERT_TRUE(cpm_test::wait_until([&] { return sim.output().find("device: ") != std::string::npos; }, 10s)) << sim.errors();
    Process bridge(hosts.program(0, {built_program("vehicle_bridge"), "--vehicle_id", "5", "--device", link}), env);
    Process fsm(hosts.program(1, {built_program("fsm_node"), "--vehicle_id", "5", "--fsm", kRoot + "/scenarios/fsm/corridor.json"}), env);
    auto logs = [&] { return "bridge:\n" + bridge.errors() + "\nfsm_node:\n" + fsm.output() + fsm.errors(); };

    // The machine on B drives the car on A across the link.
    ASSERT_TRUE(cpm_test::wait_until([&] { return first_mode_after(sim, 0, 1) != 0; }, 30s)) << logs();
    std::this_thread::sleep_for(2s);
    ASSERT_EQ(pwm_after(sim, 0).back().second, 1) << "driving when the link is cut\n" << logs();

    const uint64_t cut = cpm::get_time_ns();
    ASSERT_TRUE(hosts.cut());
    ASSERT_TRUE(cpm_test::wait_until([&] { return first_mode_after(sim, cut, 0) != 0; }, 3s)) << "the car never braked\n" << logs();
    const double braked = double(first_mode_after(sim, cut, 0) - cut) * 1e-9;
    EXPECT_LT(braked, 1.1) << "commands are fresh for 1 s, then the bridge brakes";
    std::this_thread::sleep_for(2s);
    // While cut, each side's history answers its own side: A still records the car, B kept
    // what it saw before the cut.
    EXPECT_GT(held_states(hosts, 0, cut + kSecondNs, cut + 2 * kSecondNs), 20) << "A's history records the car while cut off";
    EXPECT_GT(held_states(hosts, 1, cut - kSecondNs, cut - kSecondNs / 10), 20) << "B's history keeps what it saw";
    EXPECT_EQ(held_states(hosts, 1, cut + kSecondNs, cut + 2 * kSecondNs), 0) << "B cannot have seen the car while cut off";
    while (cpm::get_time_ns() < cut + 5 * kSecondNs) std::this_thread::sleep_for(10ms);
    EXPECT_EQ(first_mode_after(sim, cut + uint64_t(braked * 1e9), 1), 0u) << "the car stood while cut off";

    const uint64_t healed = cpm::get_time_ns();
    ASSERT_TRUE(hosts.heal());
    ASSERT_TRUE(cpm_test::wait_until([&] { return first_mode_after(sim, healed, 1) != 0; }, 10s)) << "never drove again\n" << logs();
    const double drove = double(first_mode_after(sim, healed, 1) - healed) * 1e-9;
    EXPECT_LT(drove, 2.0);
    for (Process* p : {&history_a, &history_b, &sim, &bridge, &fsm}) EXPECT_EQ(p->wait(0ms), -1) << "every process still runs\n" << logs();
    std::printf("partition: braked %.0f ms after the cut, drove again %.0f ms after the link came back\n", braked * 1000, drove * 1000);
    ::unlink(link.c_str());
}

/// The README's "A secured lab" across two machines, A and B: the lab made with `cpm security`,
/// a writer of four cars' states on A with its node's folder, on B a viewer with its own and a
/// stranger with none, each with --dds_interface, --dds_initial_peer and no shared memory.
TEST_F(Partition, ASecuredLabAcrossTwoHostsIsReadByItsViewerAndNotByAStranger)
{
    const TwoHosts& hosts = this->hosts();
    cpm_test::TempDir tmp;
    const std::string lab = tmp.file("lab-sec");
    for (std::vector<std::string> args : {std::vector<std::string>{"init", lab},
                                          {"add-node", lab, "car5", "--publish", "vehicleState"},
                                          {"add-node", lab, "viewer", "--subscribe", "vehicleState"}}) {
        args.insert(args.begin(), {built_program("cpm"), "security"});
        Process make(args);
        ASSERT_EQ(make.wait(30s), 0) << args[2] << ": " << make.errors();
    }
    Process writer(hosts.program(0, {built_program("vehicle_state_writer"), "--seconds", "60", "--security", lab + "/nodes/car5"}), env);
    Process viewer(hosts.program(1, {built_program("vehicle_state_monitor"), "--seconds", "5", "--security", lab + "/nodes/viewer"}), env);
    Process stranger(hosts.program(1, {built_program("vehicle_state_monitor"), "--seconds", "5"}), env);
    // The monitor exits 0 when a report had a valid state of every car, 2 when none had.
    EXPECT_EQ(viewer.wait(30s), 0) << viewer.output() << viewer.errors() << "\nwriter:\n" << writer.errors();
    EXPECT_NE(viewer.output().find("of 5 reports had a valid state for all 4 vehicles"), std::string::npos) << viewer.output();
    EXPECT_EQ(stranger.wait(30s), 2) << stranger.output() << stranger.errors();
    EXPECT_NE(stranger.output().find("monitor: 0 of 5 reports"), std::string::npos) << stranger.output();
    EXPECT_EQ(writer.wait(0ms), -1) << "the writer still runs\n" << writer.errors();
}

}  // namespace
