// Processes on another host, started over a real ssh into a real sshd in a network namespace
// that stands for that host: where they run, how they end, how they stop, the host's clock.
#include <cpm/Error.hpp>
#include <cpm/ProcessGroup.hpp>
#include <cpm/RemoteHost.hpp>
#include <cpm_test/Hosts.hpp>
#include <cpm_test/Isolation.hpp>
#include <cpm_test/Process.hpp>
#include <cpm_test/TempDir.hpp>

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <filesystem>
#include <fstream>
#include <optional>

using namespace std::chrono_literals;

namespace {

using cpm_test::command_line;
using cpm_test::cpm_prefix;

unsigned long netns_of(int pid)
{
    struct stat st{};
    return ::stat(("/proc/" + std::to_string(pid) + "/ns/net").c_str(), &st) == 0 ? st.st_ino : 0;
}

/// The pids in a host's namespace whose command line begins with `start` ("sleep 31": the
/// sleeps themselves, not the shell or ssh that names them).
std::vector<int> running(const cpm_test::NamespaceHosts& hosts, size_t host, const std::string& start)
{
    std::vector<int> out;
    for (int pid : hosts.pids(host)) {
        if (command_line(pid).rfind(start, 0) == 0) out.push_back(pid);
    }
    return out;
}

class RemoteHostEndToEnd : public ::testing::Test
{
protected:
    void SetUp() override
    {
        hosts_.emplace(std::vector<std::string>{"central", "car_a"});
        if (!hosts_->why_not().empty()) GTEST_SKIP() << "no namespace hosts: " << hosts_->why_not() << "; not run";
    }
    cpm_test::NamespaceHosts& hosts() { return *hosts_; }
    cpm_test::TempDir dir;

private:
    std::optional<cpm_test::NamespaceHosts> hosts_;
};

}  // namespace

TEST_F(RemoteHostEndToEnd, AProcessRunsInItsHostsNamespaceAndStoppingItStopsWhatItStarted)
{
    cpm_test::NamespaceHosts::Inside central(hosts(), 0);  // the supervisor runs on the central host
    cpm::ProcessGroup sut;
    (void)sut.start({.name = "sleeper",
                     .argv = {"/bin/sh", "-c", "trap 'echo stopping; exit 0' INT; sleep 311 & sleep 312 & wait"},
                     .log = dir.file("sleeper.log"),
                     .stop_grace = 2000ms,
                     .host = hosts().remote(1, cpm_prefix())});
    ASSERT_TRUE(cpm_test::wait_until([&] { return running(hosts(), 1, "sleep 31").size() == 2; }, 20s))
        << "not started on car_a:\n" << sut.log_text("sleeper");
    for (int pid : running(hosts(), 1, "sleep 31")) EXPECT_EQ(netns_of(pid), hosts().netns_inode(1)) << "pid " << pid << " is not on car_a";
    EXPECT_TRUE(running(hosts(), 0, "sleep 31").empty()) << "ran on the central host too";

    const auto ends = sut.stop_all();
    ASSERT_EQ(ends.size(), 1u);
    EXPECT_TRUE(ends[0].end.ok()) << ends[0].describe() << "\n" << sut.log_text("sleeper");
    EXPECT_EQ(ends[0].host, "car_a");
    EXPECT_NE(sut.log_text("sleeper").find("stopping"), std::string::npos) << "its output comes back into its log: " << sut.log_text("sleeper");
    // Its children too: nothing of it is left on the host.
    EXPECT_TRUE(cpm_test::wait_until([&] { return running(hosts(), 1, "sleep 31").empty() && running(hosts(), 1, cpm_prefix() + "/bin/cpm host run").empty(); }, 10s));
}

TEST_F(RemoteHostEndToEnd, ARemoteEndIsToldAsALocalOneWithItsHost)
{
    cpm_test::NamespaceHosts::Inside central(hosts(), 0);
    cpm::ProcessGroup sut;
    (void)sut.start({.name = "three", .argv = {"/bin/sh", "-c", "echo about to fail >&2; exit 3"}, .log = dir.file("three.log"),
                     .host = hosts().remote(1, cpm_prefix())});
    (void)sut.start({.name = "segv", .argv = {"/bin/sh", "-c", "kill -SEGV $$"}, .log = dir.file("segv.log"),
                     .host = hosts().remote(1, cpm_prefix())});
    std::vector<cpm::ProcessEvent> events;
    ASSERT_TRUE(cpm_test::wait_until([&] {
        for (auto& e : sut.poll()) events.push_back(e);
        return events.size() == 2;
    }, 20s));
    for (const auto& e : events) {
        if (e.name == "three") {
            EXPECT_EQ(e.end.code, 3);
            EXPECT_EQ(e.describe(), "exited with code 3 on car_a");
            EXPECT_NE(sut.log_text("three").find("about to fail"), std::string::npos);
        } else {
            EXPECT_EQ(e.end.signal, SIGSEGV);
            EXPECT_EQ(e.describe(), "killed by SIGSEGV on car_a");
        }
        EXPECT_FALSE(e.host_lost);
    }
}

TEST_F(RemoteHostEndToEnd, ARemoteProcessThatIgnoresTheStopIsKilledThereAndToldSoNotAsALostHost)
{
    // Deaf to SIGINT and SIGTERM (and so is its sleep): only car_a's `cpm host run` can end it,
    // with SIGKILL once the grace and SIGTERM's 2 s have passed. The run must wait for that,
    // not end the ssh itself first, which would read as a lost host.
    cpm_test::NamespaceHosts::Inside central(hosts(), 0);
    cpm::ProcessGroup sut;
    (void)sut.start({.name = "deaf",
                     .argv = {"/bin/sh", "-c", "trap '' INT TERM; echo deaf; sleep 313"},
                     .log = dir.file("deaf.log"),
                     .stop_grace = 500ms,
                     .host = hosts().remote(1, cpm_prefix())});
    ASSERT_TRUE(cpm_test::wait_until([&] { return !running(hosts(), 1, "sleep 313").empty(); }, 20s)) << sut.log_text("deaf");
    const auto ends = sut.stop_all();
    ASSERT_EQ(ends.size(), 1u);
    EXPECT_FALSE(ends[0].host_lost) << ends[0].describe();
    EXPECT_EQ(ends[0].end.signal, SIGKILL) << ends[0].describe();
    EXPECT_EQ(ends[0].describe(), "killed by SIGKILL on car_a");
    EXPECT_TRUE(cpm_test::wait_until([&] { return running(hosts(), 1, "sleep 313").empty(); }, 10s)) << "left on car_a";
}

TEST_F(RemoteHostEndToEnd, AHostWhoseLinkIsCutIsReportedLostAndWhatRunsThereStopsWithinTheLease)
{
    cpm_test::NamespaceHosts::Inside central(hosts(), 0);
    cpm::ProcessGroup sut;
    (void)sut.start({.name = "far", .argv = {"/bin/sleep", "300"}, .log = dir.file("far.log"), .host = hosts().remote(1, cpm_prefix())});
    (void)sut.start({.name = "kept", .argv = {"/bin/sleep", "301"}, .log = dir.file("kept.log"), .host = hosts().remote(0, cpm_prefix())});
    ASSERT_TRUE(cpm_test::wait_until([&] { return !running(hosts(), 1, "/bin/sleep 300").empty(); }, 20s)) << sut.log_text("far");
    ASSERT_TRUE(hosts().cut(1));
    const auto cut_at = std::chrono::steady_clock::now();
    std::vector<cpm::ProcessEvent> events;
    ASSERT_TRUE(cpm_test::wait_until([&] {
        for (auto& e : sut.poll()) events.push_back(e);
        return !events.empty();
    }, 20s)) << "a lost host was not noticed";
    EXPECT_EQ(events[0].name, "far");
    EXPECT_TRUE(events[0].host_lost) << events[0].describe();
    EXPECT_NE(events[0].describe().find("lost with host car_a"), std::string::npos) << events[0].describe();
    // Cut off, car_a's side hears nothing from the run and stops what it ran (the connection there
    // looks open: nothing else would); the central host, reached over ssh too and hearing the run
    // every second, keeps its process.
    EXPECT_TRUE(cpm_test::wait_until([&] { return running(hosts(), 1, "/bin/sleep 300").empty(); }, cpm::kRemoteLease + 10s))
        << "still running on the lost host after the lease";
    EXPECT_GE(std::chrono::steady_clock::now() - cut_at, cpm::kRemoteLease - 1s) << "stopped before its lease ran out";
    EXPECT_FALSE(running(hosts(), 0, "/bin/sleep 301").empty()) << "the process on the host still reached stopped";
    for (auto& e : sut.poll()) EXPECT_NE(e.name, "kept") << e.describe();
}

TEST_F(RemoteHostEndToEnd, AHostsClockIsMeasuredAndAHostWithoutSshIsNamed)
{
    cpm_test::NamespaceHosts::Inside central(hosts(), 0);
    const auto car = hosts().remote(1, cpm_prefix());
    const auto clock = cpm::measure_clock(car, 20);
    // One machine, one clock: the offset lies within the measurement's own bound (plus scheduling).
    EXPECT_GT(clock.rtt_ns, 0);
    EXPECT_LT(std::llabs(clock.offset_ns), clock.rtt_ns / 2 + 1'000'000) << "offset " << clock.offset_ns << " ns, rtt " << clock.rtt_ns;
    EXPECT_LT(clock.rtt_ns, 50'000'000) << "a round trip over one ssh session takes milliseconds, not a new connection each";

    hosts().stop_sshd(1);
    try {
        (void)cpm::measure_clock(car, 3);
        FAIL() << "a host without sshd answered";
    } catch (const cpm::Error& e) {
        EXPECT_NE(std::string(e.what()).find("host car_a (car_a)"), std::string::npos) << e.what();
    }
}

TEST(NamespaceHostsLeftovers, TheHostsOfAKilledTestGoBeforeTheNextTestMakesItsOwnAndARunningTestsStay)
{
    if (::geteuid() != 0) GTEST_SKIP() << "making network namespaces needs root; not run";
    const auto exists = [](const std::string& ns) { return std::system(("ip netns pids " + ns + " >/dev/null 2>&1").c_str()) == 0; };
    // As a killed test leaves them: named after a process that is gone (a child, reaped).
    const pid_t gone = ::fork();
    if (gone == 0) ::_exit(0);
    ::waitpid(gone, nullptr, 0);
    const std::string dead = "cpmh" + std::to_string(gone) + "_0", dead_switch = "cpmsw" + std::to_string(gone);
    const std::string mine = "cpmh" + std::to_string(::getpid()) + "_9";  // a running test's
    for (const auto& ns : {dead, dead_switch, mine}) ASSERT_EQ(std::system(("ip netns add " + ns).c_str()), 0) << ns;
    cpm_test::remove_stale_namespaces();
    EXPECT_FALSE(exists(dead));
    EXPECT_FALSE(exists(dead_switch));
    EXPECT_TRUE(exists(mine)) << "a running test's hosts stay";
    (void)std::system(("ip netns del " + mine).c_str());
}
