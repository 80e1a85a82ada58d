// The controller's side of the HLC contract over DDS in one process: each list runs one step, a
// list that comes while a step runs cancels it (never queued), a step that throws is counted and
// the controller goes on, the lab's stop ends start().
#include <cpm/hlc/Communicator.hpp>

#include <cpm/AsyncReader.hpp>
#include <cpm/Writer.hpp>
#include <cpm/topics.hpp>
#include <cpm_test/Dds.hpp>

#include <ReadyStatus.h>
#include <SystemTrigger.h>

#include <gtest/gtest.h>

#include <atomic>
#include <condition_variable>
#include <future>
#include <mutex>
#include <stdexcept>
#include <thread>

namespace {

namespace t = cpm::topics;
using namespace std::chrono_literals;

/// The middleware's side, played by the test: lists out, answers in.
class FakeMiddleware
{
public:
    explicit FakeMiddleware(cpm::Participant& p)
        : lists_(p, t::vehicle_state_list.name, t::vehicle_state_list.writer),
          triggers_(p, t::system_trigger.name, t::system_trigger.writer),
          answers_([this](std::vector<ReadyStatus>& s) { on_answers(s); }, p, t::ready_status.name, t::ready_status.reader)
    {
    }
    void send(uint64_t t_now)
    {
        VehicleStateList list;
        list.t_now(t_now);
        list.period_ms(100);
        list.active_vehicle_ids({1, 2});
        ASSERT_TRUE(lists_.write(list));
    }
    void stop()
    {
        SystemTrigger s;
        s.next_start().nanoseconds(UINT64_MAX);
        ASSERT_TRUE(triggers_.write(s));
    }
    /// Waits until the answers include `stamp`.
    bool wait_answer(uint64_t stamp, std::chrono::milliseconds timeout = 5s)
    {
        std::unique_lock<std::mutex> lock(mutex_);
        return changed_.wait_for(lock, timeout, [&] { return std::find(answers.begin(), answers.end(), stamp) != answers.end(); });
    }
    bool wait_matched() { return lists_.wait_for_matched(1, 5s) && triggers_.wait_for_matched(1, 5s); }
    std::vector<uint64_t> seen()
    {
        std::lock_guard<std::mutex> lock(mutex_);
        return answers;
    }

private:
    void on_answers(std::vector<ReadyStatus>& s)
    {
        std::lock_guard<std::mutex> lock(mutex_);
        for (const auto& r : s) {
            if (r.source_id() == cpm::hlc::kReadySource) answers.push_back(r.next_start_stamp().nanoseconds());
        }
        changed_.notify_all();
    }
    cpm::Writer<VehicleStateList> lists_;
    cpm::Writer<SystemTrigger> triggers_;
    std::mutex mutex_;
    std::condition_variable changed_;
    std::vector<uint64_t> answers;
    cpm::AsyncReader<ReadyStatus> answers_;
};

/// A gate a step waits at until the test opens it.
class Gate
{
public:
    void open()
    {
        std::lock_guard<std::mutex> lock(m_);
        open_ = true;
        cv_.notify_all();
    }
    void close()
    {
        std::lock_guard<std::mutex> lock(m_);
        open_ = false;
    }
    void pass()
    {
        std::unique_lock<std::mutex> lock(m_);
        cv_.wait(lock, [&] { return open_; });
    }

private:
    std::mutex m_;
    std::condition_variable cv_;
    bool open_ = true;
};

struct Controller
{
    cpm::Participant participant{cpm_test::isolated_options()};
    FakeMiddleware lab{participant};
    cpm::hlc::Communicator hlc{{1, 2}, {.participant = &participant, .stop_requested = [] { return false; }}};
    std::future<void> running;
    ~Controller() { hlc.stop(); }  // before `running` waits for start() to return
    void start() { running = std::async(std::launch::async, [this] { hlc.start(); }); }
};

constexpr uint64_t kAnnounce = UINT64_MAX;

TEST(CommunicatorTest, EachListRunsOneStepFirstTimestepOnceAndTheAnswerCarriesItsTime)
{
    Controller c;
    std::vector<uint64_t> firsts, steps;
    std::mutex m;
    c.hlc.on_first_timestep([&](const VehicleStateList& l) { std::lock_guard<std::mutex> g(m); firsts.push_back(l.t_now()); });
    c.hlc.on_each_timestep([&](const VehicleStateList& l) { std::lock_guard<std::mutex> g(m); steps.push_back(l.t_now()); });
    bool stopped = false;
    c.hlc.on_stop([&] { stopped = true; });
    c.start();
    ASSERT_TRUE(c.lab.wait_matched());
    ASSERT_TRUE(c.lab.wait_answer(kAnnounce)) << "the controller announces itself when it starts";
    for (uint64_t t : {0ull, 100ull, 200ull}) {
        c.lab.send(t);
        ASSERT_TRUE(c.lab.wait_answer(t)) << "no answer to the list of t_now " << t;
    }
    c.lab.stop();
    ASSERT_EQ(c.running.wait_for(5s), std::future_status::ready) << "the lab's stop ends start()";
    EXPECT_TRUE(stopped);
    EXPECT_EQ(firsts, (std::vector<uint64_t>{0}));
    EXPECT_EQ(steps, (std::vector<uint64_t>{0, 100, 200}));
    EXPECT_EQ(c.hlc.steps(), 3u);
    EXPECT_EQ(c.hlc.cancelled_steps(), 0u);
}

TEST(CommunicatorTest, AListThatComesWhileAStepRunsCancelsItAndIsNotQueued)
{
    Controller c;
    Gate gate;
    std::atomic<int> cancels{0};
    std::vector<uint64_t> steps;
    std::mutex m;
    std::promise<void> in_step;
    c.hlc.on_each_timestep([&](const VehicleStateList& l) {
        {
            std::lock_guard<std::mutex> g(m);
            steps.push_back(l.t_now());
        }
        if (l.t_now() == 100) in_step.set_value();
        gate.pass();
    });
    c.hlc.on_cancel_timestep([&] { ++cancels; });
    c.start();
    ASSERT_TRUE(c.lab.wait_matched());
    gate.close();
    c.lab.send(100);
    ASSERT_EQ(in_step.get_future().wait_for(5s), std::future_status::ready);
    c.lab.send(200);  // the step of 100 still runs
    for (int i = 0; i < 500 && cancels == 0; ++i) std::this_thread::sleep_for(10ms);
    EXPECT_EQ(cancels.load(), 1);
    gate.open();
    ASSERT_TRUE(c.lab.wait_answer(100));
    c.lab.send(300);
    ASSERT_TRUE(c.lab.wait_answer(300));
    c.hlc.stop();
    ASSERT_EQ(c.running.wait_for(5s), std::future_status::ready);
    EXPECT_EQ(steps, (std::vector<uint64_t>{100, 300})) << "the list of 200 came while 100 ran: never run";
    EXPECT_EQ(c.hlc.cancelled_steps(), 1u);
    const auto answers = c.lab.seen();
    EXPECT_EQ(std::count(answers.begin(), answers.end(), 200u), 0);
}

TEST(CommunicatorTest, AStepThatThrowsIsCountedAsFailedAndTheControllerGoesOn)
{
    Controller c;
    c.hlc.on_each_timestep([&](const VehicleStateList& l) {
        if (l.t_now() == 100) throw std::runtime_error("division by zero in the platoon's gap");
    });
    c.start();
    ASSERT_TRUE(c.lab.wait_matched());
    c.lab.send(100);
    for (int i = 0; i < 500 && c.hlc.failed_steps() == 0; ++i) std::this_thread::sleep_for(10ms);
    c.lab.send(200);
    ASSERT_TRUE(c.lab.wait_answer(200));
    c.hlc.stop();
    ASSERT_EQ(c.running.wait_for(5s), std::future_status::ready);
    EXPECT_EQ(c.hlc.failed_steps(), 1u);
    EXPECT_EQ(c.hlc.steps(), 1u);
    const auto answers = c.lab.seen();
    EXPECT_EQ(std::count(answers.begin(), answers.end(), 100u), 0) << "a failed step is not an answer";
}

TEST(CommunicatorTest, BadUseIsRefusedWithAClearMessage)
{
    cpm::Participant p(cpm_test::isolated_options());
    EXPECT_THROW(cpm::hlc::Communicator({}, {.participant = &p}), cpm::Error);
    try {
        cpm::hlc::Communicator c({1, 0}, {.participant = &p});
        FAIL();
    } catch (const cpm::Error& e) {
        EXPECT_NE(std::string(e.what()).find("vehicle id 0"), std::string::npos);
    }
    cpm::hlc::Communicator without_step({1}, {.participant = &p, .stop_requested = [] { return true; }});
    try {
        without_step.start();
        FAIL();
    } catch (const cpm::Error& e) {
        EXPECT_NE(std::string(e.what()).find("without on_each_timestep"), std::string::npos);
    }
}

}  // namespace
