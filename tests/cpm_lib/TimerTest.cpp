// cpm::Timer on the real clock, with the lab's start/stop triggers over DDS.
#include <cpm/Error.hpp>
#include <cpm/Logging.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/TimeMaster.hpp>
#include <cpm/Timer.hpp>
#include <cpm/init.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm_test/Dds.hpp>
#include <cpm_test/Isolation.hpp>

#include <ReadyStatus.h>
#include <SystemTrigger.h>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <unistd.h>
#include <atomic>
#include <map>
#include <mutex>
#include <thread>

using namespace std::chrono_literals;
using ::testing::HasSubstr;

namespace {

using cpm_test::kMs;

// The lab side of a synchronised start: sees ReadyStatus, sends SystemTrigger.
class TimerTest : public ::testing::Test
{
protected:
    cpm::Participant lab{cpm_test::isolated_options()};
    cpm::Participant node{cpm_test::isolated_options()};
    cpm::ReaderAbstract<ReadyStatus> ready{lab, "readyStatus", {.reliable = true, .history_depth = 10}};
    // As the lab's clock master sends them: reliable, transient-local, the latest one.
    cpm::Writer<SystemTrigger> trigger{lab, "systemTrigger", {.reliable = true, .history_depth = 1, .transient_local = true}};

    std::mutex mutex;
    std::vector<uint64_t> nominal, actual;

    cpm::Timer::Callback recorder(std::function<void(size_t)> extra = {})
    {
        return [this, extra](uint64_t t) {
            size_t n;
            {
                std::lock_guard<std::mutex> lock(mutex);
                nominal.push_back(t);
                actual.push_back(cpm::get_time_ns());
                n = nominal.size();
            }
            if (extra) extra(n);
        };
    }
    size_t calls()
    {
        std::lock_guard<std::mutex> lock(mutex);
        return nominal.size();
    }
    bool saw_ready_from(const std::string& node_id)
    {
        return cpm_test::wait_until([&] {
            for (auto& r : ready.take()) {
                if (r.source_id() == node_id) return true;
            }
            return false;
        }, 10000ms);
    }
    void send_trigger(uint64_t next_start)
    {
        ASSERT_TRUE(trigger.wait_for_matched(1, 5000ms));
        SystemTrigger t;
        t.next_start().nanoseconds(next_start);
        ASSERT_TRUE(trigger.write(t));
    }
};

}  // namespace

TEST_F(TimerTest, SynchronisedStartTicksAtAbsoluteMultiplesWithNominalTimes)
{
    // Every tick in a row: in real time, as a car's loop would run (a busy machine skips one otherwise).
    auto sut = cpm::Timer::create(node, "planner", 20 * kMs, 5 * kMs,
                                  cpm::TimerOptions{.wait_for_start = true, .simulated_time_allowed = false, .realtime = cpm::Realtime::on});
    sut->start_async(recorder());
    ASSERT_TRUE(saw_ready_from("planner")) << "no ReadyStatus from the waiting timer";
    EXPECT_EQ(calls(), 0u) << "ticked before the trigger";

    const uint64_t next_start = cpm::get_time_ns() + 200 * kMs;
    send_trigger(next_start);
    ASSERT_TRUE(cpm_test::wait_until([&] { return calls() >= 10; }));
    sut->stop();

    std::lock_guard<std::mutex> lock(mutex);
    EXPECT_EQ(sut->start_time() % (20 * kMs), 5 * kMs);
    EXPECT_GE(nominal.front(), next_start);
    EXPECT_LT(nominal.front(), next_start + 20 * kMs);
    EXPECT_EQ(nominal.front(), sut->start_time());
    for (size_t i = 1; i < nominal.size(); ++i) EXPECT_EQ(nominal[i] - nominal[i - 1], 20 * kMs) << "tick " << i;
    EXPECT_GE(actual.front(), nominal.front()) << "called before its time";
    EXPECT_LT(actual.front() - nominal.front(), 50 * kMs) << "first tick far after its nominal time";
}

TEST_F(TimerTest, OverrunningCallbackSkipsTheMissedTicksAndCountsThem)
{
    const uint64_t period = 30 * kMs;
    auto sut = cpm::Timer::create(node, "slow", period, 0, cpm::TimerOptions{.wait_for_start = false, .simulated_time_allowed = false});
    sut->start_async(recorder([](size_t n) {
        if (n == 3) std::this_thread::sleep_for(75ms);   // ~2.5 periods
        if (n == 6) std::this_thread::sleep_for(40ms);   // ~1.3 periods
    }));
    ASSERT_TRUE(cpm_test::wait_until([&] { return calls() >= 10; }));
    sut->stop();

    std::lock_guard<std::mutex> lock(mutex);
    uint64_t absent = 0;
    for (size_t i = 1; i < nominal.size(); ++i) {
        const uint64_t gap = nominal[i] - nominal[i - 1];
        ASSERT_EQ(gap % period, 0u) << "ticks off the grid at " << i;
        absent += gap / period - 1;
    }
    EXPECT_GE(nominal[3] - nominal[2], 3 * period) << "the tick after a 2.5-period overrun was not skipped";
    EXPECT_GE(nominal[6] - nominal[5], 2 * period) << "the tick after a 1.3-period overrun was not skipped";
    EXPECT_EQ(sut->missed_deadlines(), absent) << "miss count differs from the ticks skipped";
    for (size_t i = 1; i < actual.size(); ++i) {
        EXPECT_GE(actual[i], nominal[i]) << "tick " << i << " ran before its nominal time (catch-up burst)";
    }
}

TEST_F(TimerTest, ATimerThatOverrunsEveryTickWarnsOnceASecondWithACount)
{
    const std::string log = "/tmp/cpm_timer_overrun_" + std::to_string(::getpid()) + ".csv";
    cpm::Logging::instance().set_file(log);
    auto sut = cpm::Timer::create(node, "always_late", 10 * kMs, 0, cpm::TimerOptions{.wait_for_start = false, .simulated_time_allowed = false});
    std::atomic<bool> ended{false};
    sut->start_async(recorder([](size_t) { std::this_thread::sleep_for(25ms); }), [&] { ended = true; });
    ASSERT_TRUE(cpm_test::wait_until([&] { return sut->missed_deadlines() >= 100; }, 20s));
    sut->stop();
    ASSERT_TRUE(cpm_test::wait_until([&] { return ended.load(); }, 5s)) << "the timer's thread ended";
    cpm::Logging::instance().set_file("");
    std::ifstream in(log);
    size_t warnings = 0;
    std::string first, last;
    for (std::string line; std::getline(in, line);) {
        if (line.find("timer 'always_late'") == std::string::npos) continue;
        if (warnings++ == 0) first = line;
        last = line.substr(line.find("timer 'always_late'"));
    }
    std::remove(log.c_str());
    // The last word, said when it stopped, is the whole count, readable by cpm lab run.
    const auto said = cpm::timer_missed_ticks(last);
    ASSERT_TRUE(said) << last;
    EXPECT_EQ(said->first, "always_late");
    EXPECT_EQ(said->second, sut->missed_deadlines()) << last;
    // 100 and more missed ticks took at least 1.5 s (a tick and two skipped per 30 ms): not 50
    // warnings, one or two a second.
    EXPECT_GE(warnings, 1u);
    EXPECT_LE(warnings, 6u) << warnings << " warnings for " << sut->missed_deadlines() << " missed ticks";
    EXPECT_THAT(first, HasSubstr("skipped"));
    EXPECT_THAT(first, HasSubstr(",warn,"));  // through the logger (CSV: time, node, level, message)
}

TEST(TimerMissedTicks, ReadsTheNodeAndCountFromATimersWarningOnly)
{
    auto said = cpm::timer_missed_ticks("timer 'fsm_node_5': stopped; 17 ticks missed in all");
    ASSERT_TRUE(said);
    EXPECT_EQ(said->first, "fsm_node_5");
    EXPECT_EQ(said->second, 17u);
    said = cpm::timer_missed_ticks("timer 'a b': the tick at 5 ns ended 3.0 ms after ...; skipped 2 tick(s); 0 more overrun(s) "
                                   "since the last report, 1234 ticks missed in all");
    ASSERT_TRUE(said);
    EXPECT_EQ(said->first, "a b");
    EXPECT_EQ(said->second, 1234u);
    EXPECT_FALSE(cpm::timer_missed_ticks("vehicle 5: no VehicleState; braking until fresh input arrives"));
    EXPECT_FALSE(cpm::timer_missed_ticks("timer 'x': ticks missed in all"));
    EXPECT_FALSE(cpm::timer_missed_ticks("the timer 'x': 3 ticks missed in all"));
}

TEST_F(TimerTest, StopBeforeStartMeansNoCallbackEver)
{
    auto sut = cpm::Timer::create(node, "idle", 10 * kMs, 0, cpm::TimerOptions{.wait_for_start = false, .simulated_time_allowed = false});
    sut->stop();
    bool stopped = false;

    sut->start(recorder(), [&] { stopped = true; });

    EXPECT_EQ(calls(), 0u);
    EXPECT_TRUE(stopped);
}

TEST_F(TimerTest, StopDuringTheStartWaitReturnsAtOnce)
{
    auto sut = cpm::Timer::create(node, "waiting", 10 * kMs, 0, cpm::TimerOptions{.wait_for_start = true, .simulated_time_allowed = false});
    std::atomic<bool> stopped{false};
    sut->start_async(recorder(), [&] { stopped = true; });
    ASSERT_TRUE(saw_ready_from("waiting"));

    const auto t0 = std::chrono::steady_clock::now();
    sut->stop();
    ASSERT_TRUE(cpm_test::wait_until([&] { return stopped.load(); }, 2000ms));
    const auto took = std::chrono::steady_clock::now() - t0;

    EXPECT_LT(took, 500ms) << "the start wait did not notice the stop";
    EXPECT_EQ(calls(), 0u);
}

TEST_F(TimerTest, RunUntilEndsATimerStillWaitingForTheLabWhenTheStopIsAsked)
{
    // A node's Ctrl-C before the lab started (or while a simulated clock stands still) must end
    // it: nothing ticks that would ask.
    auto sut = cpm::Timer::create(node, "run_until", 10 * kMs, 0, cpm::TimerOptions{.wait_for_start = true, .simulated_time_allowed = false});
    std::atomic<bool> stop{false};
    std::atomic<bool> returned{false};
    std::thread runner([&] {
        sut->run_until([&] { return stop.load(); }, recorder());
        returned = true;
    });
    ASSERT_TRUE(saw_ready_from("run_until"));
    stop = true;
    EXPECT_TRUE(cpm_test::wait_until([&] { return returned.load(); }, 2000ms));
    if (!returned) sut->stop();  // not to hang the suite when it fails
    runner.join();
    EXPECT_EQ(calls(), 0u);
}

TEST_F(TimerTest, RunUntilTicksUntilTheStopIsAsked)
{
    auto sut = cpm::Timer::create(node, "run_until_ticks", 10 * kMs, 0, cpm::TimerOptions{.wait_for_start = false, .simulated_time_allowed = false});
    std::atomic<bool> stop{false};
    std::thread runner([&] { sut->run_until([&] { return stop.load(); }, recorder()); });
    ASSERT_TRUE(cpm_test::wait_until([&] { return calls() >= 3; }));
    stop = true;
    runner.join();
    const size_t at_end = calls();
    std::this_thread::sleep_for(30ms);
    EXPECT_EQ(calls(), at_end) << "no tick after run_until returned";
}

TEST_F(TimerTest, StopShortlyAfterStartAllowsOnlyAFewCallbacks)
{
    auto sut = cpm::Timer::create(node, "brief", 10 * kMs, 0, cpm::TimerOptions{.wait_for_start = false, .simulated_time_allowed = false});
    sut->start_async(recorder());
    ASSERT_TRUE(cpm_test::wait_until([&] { return calls() >= 1; }));

    sut->stop();
    const size_t at_stop = calls();
    std::this_thread::sleep_for(50ms);  // five periods in which nothing may happen

    EXPECT_LE(calls(), at_stop + 1);
}

TEST_F(TimerTest, SecondStartIsAnError)
{
    auto sut = cpm::Timer::create(node, "twice", 10 * kMs, 0, cpm::TimerOptions{.wait_for_start = false, .simulated_time_allowed = false});
    sut->start_async(recorder());

    EXPECT_THROW(sut->start_async(recorder()), cpm::Error);
    EXPECT_THROW(sut->start(recorder()), cpm::Error);
    sut->stop();
}

TEST_F(TimerTest, StopFromInsideTheCallbackEndsAfterThatCallback)
{
    auto sut = cpm::Timer::create(node, "self", 10 * kMs, 0, cpm::TimerOptions{.wait_for_start = false, .simulated_time_allowed = false});
    sut->start(recorder([&](size_t n) {
        if (n == 3) sut->stop();
    }));

    EXPECT_EQ(calls(), 3u);
}

TEST_F(TimerTest, StopTriggerEndsARunningTimer)
{
    auto sut = cpm::Timer::create(node, "running", 10 * kMs, 0, cpm::TimerOptions{.wait_for_start = false, .simulated_time_allowed = false});
    std::atomic<bool> stopped{false};
    sut->start_async(recorder(), [&] { stopped = true; });
    ASSERT_TRUE(cpm_test::wait_until([&] { return calls() >= 2; }));

    send_trigger(UINT64_MAX);

    EXPECT_TRUE(cpm_test::wait_until([&] { return stopped.load(); }, 5000ms));
}

TEST_F(TimerTest, APlainReliableTriggerWriterAsCpmLabsStartsTheTimers)
{
    // cpm_lab's LCC writes SystemTrigger with a reliable, volatile writer: no transient-local.
    cpm::Writer<SystemTrigger> lcc(lab, "systemTrigger", {.reliable = true, .history_depth = 1});
    auto sut = cpm::Timer::create(node, "cpm_lab_node", 10 * kMs, 0, cpm::TimerOptions{.wait_for_start = true, .simulated_time_allowed = false});
    sut->start_async(recorder());
    ASSERT_TRUE(saw_ready_from("cpm_lab_node"));
    ASSERT_TRUE(lcc.wait_for_matched(1, 5000ms)) << "no timer reader matches a volatile writer";
    SystemTrigger t;
    t.next_start().nanoseconds(cpm::get_time_ns() + 100 * kMs);
    ASSERT_TRUE(lcc.write(t));
    EXPECT_TRUE(cpm_test::wait_until([&] { return calls() >= 3; }, 5000ms)) << "the trigger started no timer";
    sut->stop();
}

TEST_F(TimerTest, OffsetNotSmallerThanPeriodIsAnErrorNamingBoth)
{
    try {
        cpm::Timer::create(node, "bad", 20 * kMs, 20 * kMs, cpm::TimerOptions{.wait_for_start = false, .simulated_time_allowed = false});
        FAIL() << "no error";
    } catch (const cpm::Error& e) {
        EXPECT_THAT(e.what(), HasSubstr("offset_ns = 20000000"));
        EXPECT_THAT(e.what(), HasSubstr("period_ns = 20000000"));
    }
    EXPECT_THROW(cpm::Timer::create(node, "zero", 0, 0, cpm::TimerOptions{.wait_for_start = false, .simulated_time_allowed = false}), cpm::Error);
}

namespace {

struct Tick
{
    uint64_t t;
    std::string node;
    bool operator<(const Tick& o) const { return t != o.t ? t < o.t : node < o.node; }
    bool operator==(const Tick& o) const { return t == o.t && node == o.node; }
};

// Three nodes (20 ms, 50 ms, 400 ms) under a simulated master for 10 simulated seconds.
// Returns the ticks in the order they ran and the real time it took.
std::vector<Tick> run_three_node_scenario(cpm::Participant& lab, cpm::Participant& node, double& real_seconds,
                                          bool& clock_matched)
{
    std::mutex mutex;
    std::vector<Tick> ticks;
    clock_matched = true;
    struct Node
    {
        std::string id;
        uint64_t period;
    };
    const std::vector<Node> nodes{{"vehicle", 20 * kMs}, {"monitor", 50 * kMs}, {"planner", 400 * kMs}};
    std::vector<std::shared_ptr<cpm::Timer>> timers;
    std::atomic<int> stopped{0};
    for (const auto& n : nodes) {
        auto timer = cpm::Timer::create(node, n.id, n.period, 0, cpm::TimerOptions{.wait_for_start = true, .simulated_time_allowed = true});
        timer->start_async(
            [&, id = n.id](uint64_t t) {
                std::lock_guard<std::mutex> lock(mutex);
                ticks.push_back({t, id});
                if (cpm::get_time_ns() != t) clock_matched = false;
            },
            [&] { ++stopped; });
        timers.push_back(timer);
    }
    cpm::TimeMaster master(lab);
    const auto t0 = std::chrono::steady_clock::now();
    master.run_simulated({"vehicle", "monitor", "planner"}, 10'000 * kMs);
    real_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    cpm_test::wait_until([&] { return stopped == 3; });
    std::lock_guard<std::mutex> lock(mutex);
    return ticks;
}

}  // namespace

TEST_F(TimerTest, SimulatedTimeRunsThreeNodesExactlyInOrderAndRepeatably)
{
    const char* argv[] = {"timer_test", "--simulated_time"};
    cpm::init(2, const_cast<char**>(argv));
    double first_seconds = 0, second_seconds = 0;
    bool first_clock = false, second_clock = false;

    auto first = run_three_node_scenario(lab, node, first_seconds, first_clock);
    auto second = run_three_node_scenario(lab, node, second_seconds, second_clock);

    std::map<std::string, std::vector<uint64_t>> by_node;
    for (const auto& t : first) by_node[t.node].push_back(t.t);
    EXPECT_EQ(by_node["vehicle"].size(), 500u);
    EXPECT_EQ(by_node["monitor"].size(), 200u);
    EXPECT_EQ(by_node["planner"].size(), 25u);
    for (auto& [id, times] : by_node) {
        const uint64_t period = id == "vehicle" ? 20 * kMs : id == "monitor" ? 50 * kMs : 400 * kMs;
        for (size_t k = 0; k < times.size(); ++k) ASSERT_EQ(times[k], k * period) << id << " tick " << k;
    }
    for (size_t i = 1; i < first.size(); ++i) {
        ASSERT_GE(first[i].t, first[i - 1].t) << "a tick at " << first[i].t << " ran after one at " << first[i - 1].t;
    }
    EXPECT_TRUE(first_clock) << "get_time_ns() differed from the nominal time inside a callback";
    EXPECT_TRUE(second_clock);
    // Same-time ticks of different nodes run concurrently; the sequence of times is the same.
    std::sort(first.begin(), first.end());
    std::sort(second.begin(), second.end());
    EXPECT_EQ(first, second);
    EXPECT_LT(first_seconds, 10.0) << "10 simulated seconds took longer than 10 real seconds";
    std::printf("10 simulated seconds took %.3f s and %.3f s of real time\n", first_seconds, second_seconds);
}

TEST_F(TimerTest, ATimerThatEndsEarlyDoesNotHoldTheSimulatedClock)
{
    const char* argv[] = {"timer_test", "--simulated_time"};
    cpm::init(2, const_cast<char**>(argv));
    // "done" stops itself in its fifth tick (a node whose work is over, e.g. a state machine in
    // its final state); "car" must still get every tick up to the end.
    auto done = cpm::Timer::create(node, "done", 20 * kMs, 0, cpm::TimerOptions{.wait_for_start = true, .simulated_time_allowed = true});
    auto car = cpm::Timer::create(node, "car", 20 * kMs, 0, cpm::TimerOptions{.wait_for_start = true, .simulated_time_allowed = true});
    std::atomic<int> done_ticks{0}, car_ticks{0};
    std::atomic<uint64_t> car_last{0};
    done->start_async([&](uint64_t) {
        if (++done_ticks == 5) done->stop();
    });
    car->start_async([&](uint64_t t) {
        ++car_ticks;
        car_last = t;
    });
    cpm::TimeMaster master(lab);
    EXPECT_NO_THROW(master.run_simulated({"done", "car"}, 1000 * kMs, 3000ms));
    EXPECT_EQ(done_ticks.load(), 5);
    EXPECT_EQ(car_ticks.load(), 50);  // 0, 20, ..., 980 ms
    EXPECT_EQ(car_last.load(), 980 * kMs);
}

TEST_F(TimerTest, TimeMasterNamesTheNodesThatNeverAnnounce)
{
    cpm::TimeMaster sut(lab);
    try {
        sut.run_simulated({"ghost"}, 1000 * kMs, 300ms, {}, 300ms);
        FAIL() << "no error";
    } catch (const cpm::Error& e) {
        EXPECT_THAT(e.what(), HasSubstr("not started within 300 ms: no announcement from 'ghost'"));
    }
}

// A process still starting (on a busy host, over ssh) may take longer to join than a step may
// take: the start has a timeout of its own.
TEST_F(TimerTest, TimeMasterWaitsItsReadyTimeoutNotItsStepTimeoutForANodeThatJoinsLate)
{
    const char* argv[] = {"timer_test", "--simulated_time"};
    cpm::init(2, const_cast<char**>(argv));
    cpm::TimeMaster master(lab);
    std::atomic<int> ticks{0};
    std::shared_ptr<cpm::Timer> late;
    std::thread joiner([&] {
        std::this_thread::sleep_for(900ms);  // three step timeouts
        late = cpm::Timer::create(node, "late", 20 * kMs, 0, cpm::TimerOptions{.wait_for_start = true, .simulated_time_allowed = true});
        late->start_async([&](uint64_t) { ++ticks; });
    });
    EXPECT_NO_THROW(master.run_simulated({"late"}, 200 * kMs, 300ms, {}, 10'000ms));
    joiner.join();
    EXPECT_EQ(ticks.load(), 10);  // 0, 20, ..., 180 ms
}

TEST_F(TimerTest, CpmLabsTwoBooleanFormStillWorks)
{
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wdeprecated-declarations"
    auto sut = cpm::Timer::create(node, "old_form", 10 * kMs, 0, false, false);
#pragma GCC diagnostic pop
    sut->start_async(recorder());
    EXPECT_TRUE(cpm_test::wait_until([&] { return calls() >= 2; }, 5000ms));  // ticked without waiting for a start
    sut->stop();
}

// A node on the simulated clock waits for a writer of each input before it announces its timer:
// it says which topics it still waits for, and goes on once they have writers.
TEST_F(TimerTest, ANodeWaitsForAWriterOfEachInputBeforeJoiningTheSimulatedClockAndSaysWhichItLacks)
{
    const std::string log = "/tmp/cpm_timer_inputs_" + std::to_string(::getpid()) + ".csv";
    cpm::Logging::instance().set_file(log);
    cpm::ReaderAbstract<ReadyStatus> first(node, "inputOne", {.reliable = true});
    cpm::ReaderAbstract<ReadyStatus> second(node, "inputTwo", {.reliable = true});
    const std::vector<cpm::TimerInput> inputs{{"inputOne", [&] { return first.matched_publications(); }},
                                              {"inputTwo", [&] { return second.matched_publications(); }}};
    // No writers: it waits until told to stop, and says so after 2 s, naming both topics.
    std::atomic<bool> stop{false};
    std::thread stopper([&] {
        std::this_thread::sleep_for(2500ms);
        stop = true;
    });
    EXPECT_FALSE(cpm::wait_for_inputs("some_node_3", inputs, [&] { return stop.load(); }));
    stopper.join();
    // One writer appears at once, the other 300 ms later: it returns once both are there.
    cpm::Writer<ReadyStatus> one(lab, "inputOne", {.reliable = true});
    std::unique_ptr<cpm::Writer<ReadyStatus>> two;
    std::thread later([&] {
        std::this_thread::sleep_for(300ms);
        two = std::make_unique<cpm::Writer<ReadyStatus>>(lab, "inputTwo", cpm::WriterOptions{.reliable = true});
    });
    const auto t0 = std::chrono::steady_clock::now();
    EXPECT_TRUE(cpm::wait_for_inputs("some_node_3", inputs, [] { return false; }));
    EXPECT_GE(std::chrono::steady_clock::now() - t0, 300ms);
    later.join();
    EXPECT_EQ(second.matched_publications(), 1u);
    cpm::Logging::instance().set_file("");
    std::ifstream in(log);
    std::string said;
    for (std::string line; std::getline(in, line);) said += line + "\n";
    std::remove(log.c_str());
    EXPECT_THAT(said, HasSubstr("some_node_3: waiting for a writer of inputOne, inputTwo before joining the lab's simulated clock"));
}
