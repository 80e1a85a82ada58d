// cpm::Logging: stderr, CSV file and the `log` topic; LogLevel over DDS.
#include <cpm/Logging.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm_test/Dds.hpp>
#include <cpm_test/Isolation.hpp>

#include <Log.h>
#include <LogLevel.h>
#include <VehicleState.h>

#include <gmock/gmock.h>
#include <cpm_test/Process.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <fstream>
#include <sstream>
#include <thread>

#include <fcntl.h>
#include <unistd.h>

using namespace std::chrono_literals;
using ::testing::HasSubstr;

namespace {

const cpm::ReaderOptions kMonitor{.reliable = true, .history_depth = 100, .transient_local = true};

class LoggingTest : public ::testing::Test
{
protected:
    void SetUp() override
    {
        cpm_test::test_domain_id();  // the default participant Logging uses joins this test's domain
        cpm::Logging::instance().set_level(cpm::Severity::info);
    }
    cpm::Participant monitor_side{cpm_test::isolated_options()};

    // Messages on `log` whose content contains `marker`, taken until `n` arrived or 5 s passed.
    std::vector<Log> messages_with(cpm::ReaderAbstract<Log>& reader, const std::string& marker, size_t n)
    {
        std::vector<Log> found;
        cpm_test::wait_until([&] {
            for (auto& l : reader.take()) {
                if (l.content().find(marker) != std::string::npos) found.push_back(l);
            }
            return found.size() >= n;
        });
        return found;
    }
};

}  // namespace

TEST_F(LoggingTest, MessageReachesStderrTheCsvFileAndTheTopic)
{
    cpm::ReaderAbstract<Log> monitor(monitor_side, "log", kMonitor);
    const std::string file = "/tmp/cpm_log_test_" + std::to_string(getpid()) + ".csv";
    const std::string err_file = file + ".stderr";
    cpm::Logging::instance().set_file(file);
    const uint64_t before = cpm::get_time_ns();

    // Capture stderr around the call.
    const int saved = dup(STDERR_FILENO);
    const int err_fd = open(err_file.c_str(), O_CREAT | O_TRUNC | O_WRONLY, 0644);
    dup2(err_fd, STDERR_FILENO);
    CPM_LOG_WARN("vehicle %d lost \"contact\"", 3);
    fflush(stderr);
    dup2(saved, STDERR_FILENO);
    close(err_fd);
    close(saved);
    cpm::Logging::instance().set_file("");

    EXPECT_THAT(cpm_test::file_text(err_file), HasSubstr("[warn]"));
    EXPECT_THAT(cpm_test::file_text(err_file), HasSubstr("vehicle 3 lost \"contact\""));
    EXPECT_THAT(cpm_test::file_text(file), HasSubstr(",warn,\"vehicle 3 lost \"\"contact\"\"\""));
    auto logs = messages_with(monitor, "vehicle 3 lost", 1);
    ASSERT_EQ(logs.size(), 1u);
    EXPECT_EQ(logs[0].log_level(), 2);
    EXPECT_FALSE(logs[0].id().empty());
    EXPECT_GE(logs[0].stamp().nanoseconds(), before);
    std::remove(file.c_str());
    std::remove(err_file.c_str());
}

TEST_F(LoggingTest, LevelFiltersAndALogLevelMessageChangesItAtRunTime)
{
    cpm::ReaderAbstract<Log> monitor(monitor_side, "log", kMonitor);
    cpm::Writer<LogLevel> level_writer(monitor_side, "logLevel", {.reliable = true, .history_depth = 1, .transient_local = true});
    // Everything received during the test: one writer's messages arrive in order.
    std::vector<std::string> contents;
    auto received = [&](const std::string& text) {
        return cpm_test::wait_until([&] {
            for (auto& l : monitor.take()) contents.push_back(l.content());
            return std::find(contents.begin(), contents.end(), text) != contents.end();
        });
    };

    CPM_LOG_DEBUG("hidden-debug-1");
    CPM_LOG_INFO("shown-info-1");
    ASSERT_TRUE(received("shown-info-1"));
    LogLevel debug;
    debug.log_level(4);
    ASSERT_TRUE(level_writer.write(debug));
    ASSERT_TRUE(cpm_test::wait_until([] { return cpm::Logging::instance().level() == cpm::Severity::debug; }))
        << "the LogLevel message did not reach the node";
    CPM_LOG_DEBUG("shown-debug-2");

    EXPECT_TRUE(received("shown-debug-2")) << "the debug message allowed by the new level did not arrive";
    EXPECT_EQ(std::count(contents.begin(), contents.end(), "hidden-debug-1"), 0) << "a debug message passed the info level";
}

TEST_F(LoggingTest, LateMonitorStillReceivesRecentMessages)
{
    CPM_LOG_ERROR("early-%d", 1);
    CPM_LOG_ERROR("early-%d", 2);

    cpm::ReaderAbstract<Log> late(monitor_side, "log", kMonitor);

    EXPECT_EQ(messages_with(late, "early-", 2).size(), 2u);
}

TEST_F(LoggingTest, LongMessageArrivesWhole)
{
    cpm::ReaderAbstract<Log> monitor(monitor_side, "log", kMonitor);
    const std::string text = "long-" + std::string(1000, 'x');

    CPM_LOG_INFO("%s", text.c_str());

    auto logs = messages_with(monitor, "long-", 1);
    ASSERT_EQ(logs.size(), 1u) << "a 1005-character message did not reach the topic";
    EXPECT_EQ(logs[0].content(), text);
}

TEST_F(LoggingTest, MessagesWrittenWhileAnotherThreadCreatesTheTopicWriterAreAllPublished)
{
    // The first message creates the log's writer; threads writing meanwhile do not wait for it
    // (their messages are queued and published once it exists). None may be lost.
    cpm::ReaderAbstract<Log> monitor(monitor_side, "log", kMonitor);
    constexpr int kThreads = 8;
    std::atomic<int> ready{0};
    std::vector<std::thread> threads;
    for (int i = 0; i < kThreads; ++i) {
        threads.emplace_back([&, i] {
            ++ready;
            while (ready < kThreads) {}
            CPM_LOG_INFO("burst-%d", i);
        });
    }
    for (auto& t : threads) t.join();
    auto logs = messages_with(monitor, "burst-", kThreads);
    std::vector<std::string> contents;
    for (const auto& l : logs) contents.push_back(l.content());
    std::sort(contents.begin(), contents.end());
    EXPECT_EQ(contents, (std::vector<std::string>{"burst-0", "burst-1", "burst-2", "burst-3", "burst-4", "burst-5", "burst-6", "burst-7"}));
}

TEST_F(LoggingTest, AnIncompatibleQosMatchIsLoggedOnceNamingTopicPolicyAndBothSides)
{
    const std::string file = "/tmp/cpm_log_qos_" + std::to_string(getpid()) + ".csv";
    cpm::Logging::instance().set_file(file);
    const std::string topic = cpm_test::unique_topic("qosMismatch");
    // A reader that wants what was sent before it joined, and a writer that keeps nothing.
    cpm::ReaderAbstract<VehicleState> wants_history(monitor_side, topic, {.reliable = true, .transient_local = true});
    cpm::Writer<VehicleState> keeps_nothing(monitor_side, topic, {.reliable = true});
    const std::string expected = "reader on topic '" + topic +
                                 "': a writer with incompatible QoS (durability) will not be matched: this reader "
                                 "requests transient_local, the writer offers volatile";
    auto count = [&] {
        std::ifstream in(file);
        size_t n = 0;
        for (std::string line; std::getline(in, line);) n += line.find(expected) != std::string::npos;
        return n;
    };
    EXPECT_TRUE(cpm_test::wait_until([&] { return count() >= 1; }, 10000ms)) << "not logged: " << expected;
    EXPECT_EQ(keeps_nothing.matched_subscriptions(), 0u);
    cpm::Writer<VehicleState> another(monitor_side, topic, {.reliable = true});  // the same mismatch again
    EXPECT_TRUE(cpm_test::holds_for([&] { return count() == 1; }, 500ms)) << count() << " reports of one mismatch";
    cpm::Logging::instance().set_file("");
    std::remove(file.c_str());
}
