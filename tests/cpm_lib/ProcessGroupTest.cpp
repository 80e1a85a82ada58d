// cpm::ProcessGroup with real programs (/bin/sh): stopped in stop order, a restartable process
// started again with its log kept, a clean exit left alone, names and hosts checked, a log's
// last lines.
#include <cpm/Error.hpp>
#include <cpm/ProcessGroup.hpp>
#include <cpm/RemoteHost.hpp>

#include <algorithm>

#include <cpm_test/TempDir.hpp>
#include <cpm_test/Isolation.hpp>

#include <gtest/gtest.h>

#include <algorithm>

#include <thread>

using namespace std::chrono_literals;

namespace {

cpm::ProcessSpec sh(const std::string& name, const std::string& script)
{
    return {.name = name, .argv = {"/bin/sh", "-c", script}};
}

/// Polls the group until `n` events came or 5 s passed.
std::vector<cpm::ProcessEvent> events_of(cpm::ProcessGroup& sut, size_t n)
{
    std::vector<cpm::ProcessEvent> all;
    (void)cpm_test::wait_until([&] {
        for (auto& e : sut.poll()) all.push_back(std::move(e));
        return all.size() >= n;
    }, 5s, 10ms);
    return all;
}

}  // namespace

TEST(ProcessGroup, StopsItsProcessesInStopOrderEachOnSigint)
{
    cpm_test::TempDir dir;
    const std::string order = dir.file("order");
    cpm::ProcessGroup sut;
    // Each says it was stopped by SIGINT, then ends; "commands" before "cars" before "history".
    auto stoppable = [&](const std::string& name, int stop_order) {
        auto spec = sh(name, "trap 'echo " + name + " >> " + order + "; exit 0' INT; echo up > " + dir.file(name) + "; while :; do sleep 0.05; done");
        spec.stop_order = stop_order;
        (void)sut.start(spec);
    };
    stoppable("history", 3);
    stoppable("car", 2);
    stoppable("commands", 1);
    ASSERT_TRUE(cpm_test::wait_until([&] { return dir.read("history") == "up\n" && dir.read("car") == "up\n" && dir.read("commands") == "up\n"; }, 5s, 10ms));
    const auto ends = sut.stop_all();
    EXPECT_EQ(dir.read("order"), "commands\ncar\nhistory\n");
    ASSERT_EQ(ends.size(), 3u);
    for (const auto& e : ends) EXPECT_TRUE(e.end.ok()) << e.name << " " << e.end.describe();
    EXPECT_EQ(sut.names(), (std::vector<std::string>{"history", "car", "commands"}));
}

TEST(ProcessGroup, AFrozenProcessIsContinuedToActOnItsStopNotLeftToTheKill)
{
    // Frozen (SIGSTOP, Ctrl-Z, a test's stalled node): a signal waits until the process is
    // continued, so the stop sends SIGCONT after it, as systemd does. Without, it waited the
    // grace and the SIGTERM's 2 s, then killed it with SIGKILL.
    cpm_test::TempDir dir;
    cpm::ProcessGroup sut;
    auto spec = sh("frozen", "trap 'echo stopped > " + dir.file("said") + "; exit 0' INT; echo up > " + dir.file("up") +
                                 "; while :; do sleep 0.05; done");
    spec.stop_grace = 20s;  // a grace this long: only a stop it acted on ends in time for the test's own limit
    cpm::ChildProcess& child = sut.start(spec);
    ASSERT_TRUE(cpm_test::wait_until([&] { return dir.read("up") == "up\n"; }, 5s, 10ms));
    child.signal(SIGSTOP);
    const auto ends = sut.stop_all();
    ASSERT_EQ(ends.size(), 1u);
    EXPECT_TRUE(ends[0].end.ok()) << ends[0].end.describe();
    EXPECT_EQ(dir.read("said"), "stopped\n");
}

TEST(ProcessGroup, ARestartableProcessIsStartedAgainAndItsLogKept)
{
    cpm_test::TempDir dir;
    cpm::ProcessGroup sut;
    auto flaky = sh("flaky", "echo run >> " + dir.file("runs") + "; echo 'about to fail'; exit 3");
    flaky.log = dir.file("flaky.log");
    flaky.restart = true;
    (void)sut.start(flaky);
    const auto events = events_of(sut, 2);
    ASSERT_GE(events.size(), 2u);
    EXPECT_EQ(events[0].name, "flaky");
    EXPECT_EQ(events[0].end.describe(), "exited with code 3");
    EXPECT_TRUE(events[0].restarted);
    EXPECT_EQ(events[1].restarts, 2);
    EXPECT_GE(sut.restarts_of("flaky"), 2);
    const std::string log = dir.read("flaky.log");
    EXPECT_EQ(log.rfind("about to fail\n\n--- restarted ---\nabout to fail\n", 0), 0u) << log;
    (void)sut.stop_all();
    const std::string tail = sut.tail("flaky", 4);  // its last lines, indented, for a message
    EXPECT_NE(tail.find("    about to fail\n"), std::string::npos) << tail;
    EXPECT_NE(tail.find("    --- restarted ---\n"), std::string::npos) << tail;
    EXPECT_EQ(std::count(tail.begin(), tail.end(), '\n'), 4) << tail;
}

TEST(ProcessGroup, AProcessThatIsDoneIsNotRestarted)
{
    cpm::ProcessGroup sut;
    auto done = sh("done", "exit 0");
    done.restart = true;
    (void)sut.start(done);
    const auto events = events_of(sut, 1);
    ASSERT_EQ(events.size(), 1u);
    EXPECT_TRUE(events[0].end.ok());
    EXPECT_FALSE(events[0].restarted);
    std::this_thread::sleep_for(100ms);
    EXPECT_TRUE(sut.poll().empty()) << "told once";
    EXPECT_EQ(sut.end_of("done")->describe(), "exited with code 0");
}

TEST(ProcessGroup, ANameTakenOrAMissingProgramIsAnErrorNamingIt)
{
    cpm::ProcessGroup sut;
    (void)sut.start(sh("a", "sleep 5"));
    try {
        (void)sut.start(sh("a", "true"));
        FAIL();
    } catch (const cpm::Error& e) {
        EXPECT_STREQ(e.what(), "process group: the name 'a' is taken");
    }
    try {
        (void)sut.start({.name = "ghost", .argv = {"/nonexistent/program"}});
        FAIL();
    } catch (const cpm::Error& e) {
        EXPECT_NE(std::string(e.what()).find("/nonexistent/program"), std::string::npos) << e.what();
    }
    EXPECT_EQ(sut.names(), std::vector<std::string>{"a"}) << "a refused spec leaves nothing behind";
}

TEST(RemoteHost, AProgramThereRunsTiedToItsSshWithEveryArgumentQuotedAsGiven)
{
    const cpm::RemoteHost car{.name = "car5", .ssh = "pi@10.0.0.5", .ssh_options = {"-F", "/lab/ssh config"}, .cpm_prefix = "/opt/cpm"};
    const auto argv = cpm::remote_command(car, {"/opt/cpm/bin/fsm_node", "--fsm", "it's a car.json", "$(reboot)"}, std::chrono::seconds(2));
    ASSERT_GE(argv.size(), 5u);
    EXPECT_EQ(argv[0], "/usr/bin/ssh");
    EXPECT_NE(std::find(argv.begin(), argv.end(), "BatchMode=yes"), argv.end()) << "never a password prompt";
    const auto config = std::find(argv.begin(), argv.end(), "-F");
    ASSERT_NE(config, argv.end());
    EXPECT_EQ(*(config + 1), "/lab/ssh config");
    EXPECT_EQ(argv[argv.size() - 3], "pi@10.0.0.5");
    EXPECT_EQ(argv[argv.size() - 2], "--");
    // One word for the remote shell each, nothing it would expand.
    EXPECT_EQ(argv.back(), "'/opt/cpm/bin/cpm' 'host' 'run' '--grace' '2000ms' '--lease' '10000ms' '--' '/opt/cpm/bin/fsm_node' '--fsm' 'it'\\''s a car.json' '$(reboot)'");
    EXPECT_TRUE(cpm::RemoteHost{}.is_local());
}
