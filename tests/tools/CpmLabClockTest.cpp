// `cpm lab clock` as a real process driving timers in this test process.
#include <cpm/Logging.hpp>
#include <cpm/Timer.hpp>
#include <cpm/get_parameter.hpp>
#include <cpm/init.hpp>
#include <cpm_test/Dds.hpp>
#include <cpm_test/Isolation.hpp>
#include <cpm_test/Process.hpp>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <atomic>
#include <csignal>
#include <fstream>

#include <unistd.h>

using namespace std::chrono_literals;
using ::testing::HasSubstr;

namespace {
constexpr uint64_t kMs = 1'000'000;
}

TEST(CpmLabClock, SimulatedModeDrivesTheNamedTimersToTheEndAndStopsThem)
{
    const char* argv[] = {"cli_test", "--simulated_time"};
    cpm::init(2, const_cast<char**>(argv));
    cpm::Participant node(cpm_test::isolated_options());
    std::atomic<int> vehicle_ticks{0}, planner_ticks{0}, stopped{0};
    auto vehicle = cpm::Timer::create(node, "vehicle", 20 * kMs, 0, cpm::TimerOptions{.wait_for_start = true, .simulated_time_allowed = true});
    auto planner = cpm::Timer::create(node, "planner", 400 * kMs, 0, cpm::TimerOptions{.wait_for_start = true, .simulated_time_allowed = true});
    vehicle->start_async([&](uint64_t) { ++vehicle_ticks; }, [&] { ++stopped; });
    planner->start_async([&](uint64_t) { ++planner_ticks; }, [&] { ++stopped; });

    cpm_test::Process sut({cpm_test::built_program("cpm"), "lab", "clock", "--simulated", "--nodes",
                           "vehicle,planner", "--until", "2s"});

    ASSERT_EQ(sut.wait(30000ms), 0) << sut.output();
    EXPECT_THAT(sut.output(), HasSubstr("simulated 2.000 s"));
    EXPECT_TRUE(cpm_test::wait_until([&] { return stopped == 2; })) << "the timers were not stopped";
    EXPECT_EQ(vehicle_ticks, 100);
    EXPECT_EQ(planner_ticks, 5);
}

TEST(CpmLabClock, RealTimeModeStartsWaitingTimersTogetherAndStopsThem)
{
    cpm::Participant node(cpm_test::isolated_options());
    std::atomic<uint64_t> first_a{0}, first_b{0};
    std::atomic<int> stopped{0};
    auto a = cpm::Timer::create(node, "a", 20 * kMs, 0, cpm::TimerOptions{.wait_for_start = true, .simulated_time_allowed = false});
    auto b = cpm::Timer::create(node, "b", 50 * kMs, 10 * kMs, cpm::TimerOptions{.wait_for_start = true, .simulated_time_allowed = false});
    a->start_async([&](uint64_t t) { if (!first_a) first_a = t; }, [&] { ++stopped; });
    b->start_async([&](uint64_t t) { if (!first_b) first_b = t; }, [&] { ++stopped; });

    cpm_test::Process sut({cpm_test::built_program("cpm"), "lab", "clock", "--nodes", "a,b", "--start-delay",
                           "300ms", "--duration", "400ms"});

    ASSERT_EQ(sut.wait(30000ms), 0) << sut.output();
    EXPECT_TRUE(cpm_test::wait_until([&] { return stopped == 2; })) << "the timers were not stopped";
    ASSERT_NE(first_a.load(), 0u);
    ASSERT_NE(first_b.load(), 0u);
    // Both started from the same announced start: their first ticks lie within one period of it.
    EXPECT_LT(first_a > first_b ? first_a - first_b : first_b - first_a, 50 * kMs);
    EXPECT_EQ(first_b % (50 * kMs), 10 * kMs);
}

TEST(CpmLabClock, BadArgumentsExitWithCode2AndNameTheProblem)
{
    cpm_test::test_domain_id();
    cpm_test::Process no_nodes({cpm_test::built_program("cpm"), "lab", "clock", "--simulated", "--until", "1s"});
    cpm_test::Process bad_duration({cpm_test::built_program("cpm"), "lab", "clock", "--nodes", "a", "--simulated",
                                    "--until", "ten"});
    cpm_test::Process unknown({cpm_test::built_program("cpm"), "lab", "clocks"});

    cpm_test::Process bad_real_duration({cpm_test::built_program("cpm"), "lab", "clock", "--nodes", "a", "--duration", "abc"});

    EXPECT_EQ(no_nodes.wait(10000ms), 2);
    EXPECT_THAT(no_nodes.errors(), HasSubstr("cpm lab clock: --nodes is required"));
    EXPECT_EQ(bad_duration.wait(10000ms), 2);
    EXPECT_THAT(bad_duration.errors(), HasSubstr("--until: 'ten' is not a duration"));
    EXPECT_EQ(unknown.wait(10000ms), 2);
    EXPECT_THAT(unknown.errors(), HasSubstr("unknown command 'cpm lab clocks'"));
    // Checked before it waits (up to 30 s) for the nodes to be ready.
    EXPECT_EQ(bad_real_duration.wait(10000ms), 2);
    EXPECT_THAT(bad_real_duration.errors(), HasSubstr("--duration: 'abc' is not a duration"));
}

TEST(CpmParamServe, ServesAFileToClientsUntilStopped)
{
    cpm_test::test_domain_id();
    const std::string file = "/tmp/cpm_param_serve_" + std::to_string(getpid()) + ".json";
    std::ofstream(file) << R"({"max_speed": 1.5, "vehicles": [1, 3, 7]})";

    cpm_test::Process sut({cpm_test::built_program("cpm"), "param", "serve", file});

    EXPECT_EQ(cpm::parameter_double("max_speed", 10000ms), 1.5);
    EXPECT_EQ(cpm::parameter_ints("vehicles"), (std::vector<int32_t>{1, 3, 7}));
    // The server answers as soon as it has loaded the file, a moment before it says so.
    EXPECT_TRUE(cpm_test::wait_until([&] { return sut.output().find("serving 2 parameters") != std::string::npos; }, std::chrono::seconds(10))) << sut.output();
    sut.kill(SIGTERM);
    EXPECT_EQ(sut.wait(5000ms), 0);
    std::remove(file.c_str());
}

TEST(CpmParamServe, BadFileExitsNonZeroNamingIt)
{
    cpm_test::test_domain_id();
    cpm_test::Process sut({cpm_test::built_program("cpm"), "param", "serve", "/nonexistent/params.json"});

    EXPECT_EQ(sut.wait(10000ms), 1);
    EXPECT_THAT(sut.errors(), HasSubstr("/nonexistent/params.json: cannot open the parameter file: no such file"));
}

TEST(CpmTopicEcho, LogShowsMessagesAsTableAndJson)
{
    cpm_test::test_domain_id();
    cpm::Logging::instance().set_level(cpm::Severity::info);
    CPM_LOG_WARN("echo-check %d", 1);
    CPM_LOG_INFO("echo-check %d", 2);

    cpm_test::Process table({cpm_test::built_program("cpm"), "topic", "echo", "log", "--count", "2"});
    cpm_test::Process json({cpm_test::built_program("cpm"), "topic", "echo", "log", "--json", "--count", "2"});

    ASSERT_EQ(table.wait(10000ms), 0) << table.output();
    ASSERT_EQ(json.wait(10000ms), 0) << json.output();
    EXPECT_THAT(table.output(), HasSubstr("warn   echo-check 1"));
    EXPECT_THAT(table.output(), HasSubstr("info   echo-check 2"));
    EXPECT_THAT(json.output(), HasSubstr(R"("content":"echo-check 1")"));
    EXPECT_THAT(json.output(), HasSubstr(R"("log_level":2)"));
}

TEST(CpmTopicEcho, ATopicNobodyWritesIsNamedWithExitCode1)
{
    cpm_test::test_domain_id();
    cpm_test::Process sut({cpm_test::built_program("cpm"), "topic", "echo", "vehicleState", "--wait", "300ms"});

    EXPECT_EQ(sut.wait(10000ms), 1);
    EXPECT_THAT(sut.errors(), HasSubstr("no writer of topic 'vehicleState' appeared"));
}
