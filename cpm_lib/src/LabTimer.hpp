#pragma once
#include <cpm/LogThrottle.hpp>
#include <cpm/AsyncReader.hpp>
#include <cpm/Timer.hpp>
#include <cpm/Writer.hpp>

#include <ReadyStatus.h>
#include <SystemTrigger.h>

#include <atomic>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <thread>

namespace cpm::detail {

/// cpm::Timer. Real time: a timerfd armed with absolute CLOCK_REALTIME deadlines and an
/// eventfd that stop() writes to, polled together, so a stop ends any wait at once.
/// Simulated time: announces its next nominal tick in ReadyStatus and ticks when a
/// SystemTrigger names exactly that time (TimeMaster drives the triggers).
class LabTimer : public Timer
{
public:
    LabTimer(Participant& participant, std::string node_id, uint64_t period_ns, uint64_t offset_ns,
             bool wait_for_start, bool simulated, Realtime realtime = Realtime::off,
             int realtime_priority = realtime_priority::timer);
    ~LabTimer() override;

    void start(Callback callback, std::function<void()> on_stop) override;
    void start_async(Callback callback, std::function<void()> on_stop) override;
    void stop() override;

    uint64_t start_time() const override { return start_time_; }
    uint64_t missed_deadlines() const override { return missed_; }
    uint64_t period_ns() const override { return period_ns_; }
    uint64_t offset_ns() const override { return offset_ns_; }

private:
    // The timer loop until stopped, then on_stop.
    void run(const Callback& callback, const std::function<void()>& on_stop);
    void run_real_time(const Callback& callback);
    void run_simulated(const Callback& callback);
    void announce(uint64_t next_tick_ns);
    // Announces readiness until a start trigger (its next_start) or a stop; 0 when stopped.
    uint64_t wait_for_trigger();
    // Waits until the absolute time t or a stop; false when stopped.
    bool sleep_until(uint64_t t_ns);
    void on_trigger(std::vector<SystemTrigger>& triggers);

    const std::string node_id_;
    const uint64_t period_ns_;
    const uint64_t offset_ns_;
    const bool wait_for_start_;
    const bool simulated_;
    const Realtime realtime_;
    const int realtime_priority_;
    int timer_fd_ = -1;
    int stop_fd_ = -1;
    std::atomic<bool> started_{false};
    std::atomic<bool> stopping_{false};
    std::atomic<uint64_t> start_time_{0};
    std::atomic<uint64_t> missed_{0};
    LogThrottle overrun_log_;  ///< the timer's thread only
    uint64_t missed_reported_ = 0;  ///< the count the last warning said (the timer's thread only)

    std::mutex trigger_mutex_;
    std::condition_variable trigger_changed_;
    uint64_t next_start_ = 0;      // the largest next_start received (the lab clock only advances)
    uint64_t trigger_count_ = 0;   // triggers received (a simulated trigger may be 0)
    /// The lab time the timer's thread waits for: a trigger before it (another node's tick) is
    /// counted without waking the thread. 0: every trigger wakes it.
    uint64_t wake_at_ = 0;

    std::unique_ptr<Writer<ReadyStatus>> ready_writer_;
    std::unique_ptr<AsyncReader<SystemTrigger>> trigger_reader_;
    std::unique_ptr<AsyncReader<SystemTrigger>> live_trigger_reader_;  ///< matches volatile writers too
    std::thread thread_;
};

}  // namespace cpm::detail
