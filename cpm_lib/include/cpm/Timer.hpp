#pragma once
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <cpm/Participant.hpp>
#include <cpm/Realtime.hpp>

namespace cpm {

/// How a Timer starts and which clock it follows (defaults as cpm_lab's).
struct TimerOptions
{
    /// Announce ReadyStatus and wait for the lab's SystemTrigger before the first tick; else
    /// tick from now on.
    bool wait_for_start = true;
    /// Under --simulated_time, follow the lab's simulated clock; else always the real clock.
    bool simulated_time_allowed = true;
    /// Set: on the lab's simulated clock (true) or the real one (false) whatever --simulated_time
    /// says, the process's own cpm::get_time_ns() unchanged. For a process that joins a simulated
    /// run's clock and keeps the wall clock for itself (cpm_history --simulated-clock).
    std::optional<bool> simulated_time;
    /// Run the timer's thread (the callbacks) SCHED_FIFO at realtime_priority; unset: cpm::init's
    /// --realtime. With Realtime::required and no privilege, Timer::create throws cpm::Error.
    std::optional<Realtime> realtime;
    int realtime_priority = cpm::realtime_priority::timer;  ///< 1..99
};

/// Calls back at absolute lab times k * period + offset (cpm_lab's Timer).
///
/// With wait_for_start, the timer announces `ReadyStatus{source_id = node_id}` on
/// `readyStatus` about once a second and waits for a `SystemTrigger` on `systemTrigger`; its
/// first tick is the first k * period + offset >= next_start. A trigger of UINT64_MAX stops
/// every timer (also while running). The callback receives the *nominal* tick time. When a
/// callback overruns, the missed ticks are skipped (no catch-up burst), counted and logged.
/// stop() works from any thread — before start, during the start wait, while running, and
/// from inside the callback — and returns at once. Throws cpm::Error on invalid arguments and
/// on a second start.
class Timer
{
public:
    using Callback = std::function<void(uint64_t t_nominal_ns)>;

    /// A timer on the real clock (CLOCK_REALTIME); with --simulated_time and
    /// simulated_time_allowed, on the lab's simulated clock: it then announces its next tick in
    /// ReadyStatus.next_start_stamp and ticks when a SystemTrigger names exactly that time
    /// (cpm::TimeMaster, `cpm lab clock --simulated`), whatever wait_for_start says.
    /// offset_ns must be < period_ns. The participant (default: the process's) carries the
    /// ready announcements and the start/stop triggers.
    static std::shared_ptr<Timer> create(const std::string& node_id, uint64_t period_ns, uint64_t offset_ns,
                                         TimerOptions options = {});
    static std::shared_ptr<Timer> create(Participant& participant, const std::string& node_id, uint64_t period_ns,
                                         uint64_t offset_ns, TimerOptions options = {});
    /// cpm_lab's form, two booleans in a row; say which is which with TimerOptions instead.
    [[deprecated("use Timer::create(..., TimerOptions{.wait_for_start = ..., .simulated_time_allowed = ...})")]]
    static std::shared_ptr<Timer> create(const std::string& node_id, uint64_t period_ns, uint64_t offset_ns,
                                         bool wait_for_start, bool simulated_time_allowed)
    {
        return create(node_id, period_ns, offset_ns, TimerOptions{wait_for_start, simulated_time_allowed});
    }
    [[deprecated("use Timer::create(..., TimerOptions{.wait_for_start = ..., .simulated_time_allowed = ...})")]]
    static std::shared_ptr<Timer> create(Participant& participant, const std::string& node_id, uint64_t period_ns,
                                         uint64_t offset_ns, bool wait_for_start, bool simulated_time_allowed)
    {
        return create(participant, node_id, period_ns, offset_ns, TimerOptions{wait_for_start, simulated_time_allowed});
    }

    virtual ~Timer() = default;

    /// Runs the timer on the calling thread until stop() or a stop trigger; then calls
    /// on_stop (if given) and returns.
    virtual void start(Callback callback, std::function<void()> on_stop = {}) = 0;
    /// The same on a thread the timer owns; stop() or destroying the timer ends it.
    virtual void start_async(Callback callback, std::function<void()> on_stop = {}) = 0;
    /// Ends the timer; safe from any thread, any time, more than once.
    virtual void stop() = 0;
    /// A node's loop: start() on the calling thread until `stop_requested()` turns true (e.g.
    /// cpm::cli::stop_requested after SIGINT) or the lab stops the timers. It is asked before
    /// every tick and every 50 ms between, so it also ends a timer still waiting for the lab's
    /// start or for a simulated clock that does not move. `stop_requested` is called from a
    /// second thread too, so it must be safe to call from any thread (an atomic flag).
    void run_until(const std::function<bool()>& stop_requested, Callback callback);

    /// The nominal time of the first tick (0 before the start is known).
    virtual uint64_t start_time() const = 0;
    /// Ticks skipped because a callback overran.
    virtual uint64_t missed_deadlines() const = 0;
    virtual uint64_t period_ns() const = 0;
    virtual uint64_t offset_ns() const = 0;
};

/// A timer says its missed ticks in the log (at most once a second while it overruns, and once
/// more when it stops): "timer '<node_id>': ...; <N> ticks missed in all". Reads the node id and
/// N back from such a message (cpm lab run counts the lab's missed deadlines this way); nullopt
/// for any other message.
std::optional<std::pair<std::string, uint64_t>> timer_missed_ticks(const std::string& message);

/// An input of a node: its topic and how many writers its reader has matched.
struct TimerInput
{
    std::string topic;
    std::function<size_t()> matched_writers;
};

/// On the lab's simulated clock, lab time moves on as soon as every timer has finished its tick:
/// a sample written before its reader had matched is lost for good, and what a run does would
/// depend on how fast discovery was. A node on that clock calls this before it creates its
/// timer (which announces it to the clock): it waits until each input has a writer. After 2 s
/// it says once, as `node_id`, which topics it still waits for. False when `stop_requested()`
/// turned true first.
bool wait_for_inputs(const std::string& node_id, const std::vector<TimerInput>& inputs, const std::function<bool()>& stop_requested);

}  // namespace cpm
