#include "LabTimer.hpp"

#include <cpm/Logging.hpp>
#include <cpm/topics.hpp>

#include "lab_clock.hpp"
#include "lab_topics.hpp"

#include "log_internal.hpp"

#include <cpm/Error.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/init.hpp>

#include <algorithm>
#include <condition_variable>
#include <mutex>
#include <thread>
#include <cctype>
#include <cerrno>
#include <cstring>

#include <poll.h>
#include <sys/eventfd.h>
#include <sys/timerfd.h>
#include <unistd.h>

namespace cpm {

namespace {
constexpr auto kReadyAnnouncePeriod = std::chrono::seconds(1);
}  // namespace

std::shared_ptr<Timer> Timer::create(const std::string& node_id, uint64_t period_ns, uint64_t offset_ns,
                                     TimerOptions options)
{
    return create(Participant::default_participant(), node_id, period_ns, offset_ns, options);
}

std::shared_ptr<Timer> Timer::create(Participant& participant, const std::string& node_id, uint64_t period_ns,
                                     uint64_t offset_ns, TimerOptions options)
{
    const bool simulated = options.simulated_time.value_or(init_settings().simulated_time && options.simulated_time_allowed);
    if (options.realtime_priority < 1 || options.realtime_priority > 99) {
        throw Error("Timer '" + node_id + "': realtime_priority " + std::to_string(options.realtime_priority) +
                    " is outside SCHED_FIFO's 1..99");
    }
    const Realtime realtime = options.realtime.value_or(init_settings().realtime);
    if (realtime == Realtime::required) {
        if (const std::string missing = realtime_missing(options.realtime_priority); !missing.empty())
            throw Error("Timer '" + node_id + "': real time is required and not permitted: " + missing);
    }
    return std::make_shared<detail::LabTimer>(participant, node_id, period_ns, offset_ns, options.wait_for_start, simulated,
                                              realtime, options.realtime_priority);
}

std::optional<std::pair<std::string, uint64_t>> timer_missed_ticks(const std::string& message)
{
    static const std::string head = "timer '", tail = " ticks missed in all";
    if (message.rfind(head, 0) != 0) return std::nullopt;
    const size_t id_end = message.find("': ", head.size());
    const size_t count_end = message.rfind(tail);
    if (id_end == std::string::npos || count_end == std::string::npos || count_end <= id_end) return std::nullopt;
    size_t count_begin = count_end;
    while (count_begin > id_end && std::isdigit(static_cast<unsigned char>(message[count_begin - 1]))) --count_begin;
    if (count_begin == count_end || count_end - count_begin > 19) return std::nullopt;  // not a count a timer says
    return std::pair<std::string, uint64_t>(message.substr(head.size(), id_end - head.size()),
                                            std::stoull(message.substr(count_begin, count_end - count_begin)));
}

void Timer::run_until(const std::function<bool()>& stop_requested, Callback callback)
{
    std::mutex mutex;
    std::condition_variable ended;
    bool done = false;
    std::thread watcher([&] {
        std::unique_lock<std::mutex> lock(mutex);
        while (!done) {
            if (stop_requested()) {
                stop();
                return;
            }
            ended.wait_for(lock, std::chrono::milliseconds(50));
        }
    });
    start([&](uint64_t t_nominal) {
        if (stop_requested()) {
            stop();
            return;
        }
        callback(t_nominal);
    });
    {
        std::lock_guard<std::mutex> lock(mutex);
        done = true;
    }
    ended.notify_all();
    watcher.join();
}

namespace detail {

LabTimer::LabTimer(Participant& participant, std::string node_id, uint64_t period_ns, uint64_t offset_ns,
                   bool wait_for_start, bool simulated, Realtime realtime, int realtime_priority)
    : node_id_(std::move(node_id)),
      period_ns_(period_ns),
      offset_ns_(offset_ns),
      wait_for_start_(wait_for_start || simulated),
      simulated_(simulated),
      realtime_(realtime),
      realtime_priority_(realtime_priority)
{
    if (node_id_.empty()) throw Error("Timer: node_id is empty");
    if (period_ns_ == 0) throw Error("Timer '" + node_id_ + "': period_ns must be > 0");
    if (offset_ns_ >= period_ns_) {
        throw Error("Timer '" + node_id_ + "': offset_ns = " + std::to_string(offset_ns_) +
                    " must be smaller than period_ns = " + std::to_string(period_ns_));
    }
    timer_fd_ = timerfd_create(CLOCK_REALTIME, TFD_CLOEXEC);
    stop_fd_ = eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK);
    if (timer_fd_ < 0 || stop_fd_ < 0) {
        if (timer_fd_ >= 0) close(timer_fd_);
        if (stop_fd_ >= 0) close(stop_fd_);
        throw Error("Timer '" + node_id_ + "': cannot create timerfd/eventfd: " + std::strerror(errno));
    }
    // The trigger reader exists from construction on, so a trigger sent while the program
    // is still preparing is not missed; a stop trigger (UINT64_MAX) ends every timer.
    if (wait_for_start_) {
        ready_writer_ = std::make_unique<Writer<ReadyStatus>>(participant, topics::ready_status.name, topics::ready_status.writer);
    }
    // on_trigger is short (a lock, a notify): it runs on the DDS thread that delivers the
    // trigger, one thread hop less per step of a simulated clock.
    trigger_reader_ = std::make_unique<AsyncReader<SystemTrigger>>([this](std::vector<SystemTrigger>& triggers) { on_trigger(triggers); },
                                                                   participant, topics::system_trigger.name,
                                                                   topics::system_trigger.reader.on_dds_thread());
    live_trigger_reader_ = std::make_unique<AsyncReader<SystemTrigger>>(
        [this](std::vector<SystemTrigger>& triggers) { on_trigger(triggers); }, participant, topics::system_trigger.name,
        live_reader_options(topics::system_trigger).on_dds_thread());
}

LabTimer::~LabTimer()
{
    stop();
    if (thread_.joinable()) {
        if (thread_.get_id() == std::this_thread::get_id()) {
            thread_.detach();
        } else {
            thread_.join();
        }
    }
    trigger_reader_.reset();  // no more on_trigger calls before the descriptors go
    live_trigger_reader_.reset();
    close(timer_fd_);
    close(stop_fd_);
}

void LabTimer::on_trigger(std::vector<SystemTrigger>& triggers)
{
    bool wake = false;
    for (const auto& trigger : triggers) {
        const uint64_t next_start = trigger.next_start().nanoseconds();
        if (next_start == kStopTrigger) {
            stop();
            continue;
        }
        std::lock_guard<std::mutex> lock(trigger_mutex_);
        // The lab clock only moves forward: a late-delivered older trigger must not wind it back.
        if (trigger_count_ == 0 || next_start > next_start_) next_start_ = next_start;
        ++trigger_count_;
        // Another node's tick leaves this timer asleep: on the simulated clock most steps are
        // other nodes', and a needless wake-up costs the step a context switch on a busy core.
        wake = wake || next_start_ >= wake_at_;
    }
    if (wake) trigger_changed_.notify_all();
}

void LabTimer::stop()
{
    stopping_ = true;
    const uint64_t one = 1;
    [[maybe_unused]] const ssize_t n = write(stop_fd_, &one, sizeof one);
    std::lock_guard<std::mutex> lock(trigger_mutex_);
    trigger_changed_.notify_all();
}

void LabTimer::announce(uint64_t next_tick_ns)
{
    ReadyStatus ready;
    ready.source_id(node_id_);
    ready.next_start_stamp().nanoseconds(next_tick_ns);
    (void)ready_writer_->write(ready);
}

uint64_t LabTimer::wait_for_trigger()
{
    std::unique_lock<std::mutex> lock(trigger_mutex_);
    while (!stopping_ && trigger_count_ == 0) {
        lock.unlock();
        announce(0);
        lock.lock();
        trigger_changed_.wait_for(lock, kReadyAnnouncePeriod, [&] { return stopping_ || trigger_count_ != 0; });
    }
    return stopping_ ? 0 : next_start_;
}

bool LabTimer::sleep_until(uint64_t t_ns)
{
    itimerspec spec{};
    spec.it_value.tv_sec = static_cast<time_t>(t_ns / 1'000'000'000ull);
    spec.it_value.tv_nsec = static_cast<long>(t_ns % 1'000'000'000ull);
    if (timerfd_settime(timer_fd_, TFD_TIMER_ABSTIME, &spec, nullptr) != 0) {
        log_error("timer '" + node_id_ + "': timerfd_settime failed: " + std::strerror(errno));
        return false;
    }
    pollfd fds[2] = {{timer_fd_, POLLIN, 0}, {stop_fd_, POLLIN, 0}};
    while (!stopping_) {
        const int ready = poll(fds, 2, -1);
        if (ready < 0 && errno == EINTR) continue;
        if (ready < 0) {
            log_error("timer '" + node_id_ + "': poll failed: " + std::strerror(errno));
            return false;
        }
        if (fds[1].revents != 0) return false;
        if (fds[0].revents != 0) {
            uint64_t expirations = 0;
            [[maybe_unused]] const ssize_t n = read(timer_fd_, &expirations, sizeof expirations);
            return !stopping_;
        }
    }
    return false;
}

void LabTimer::start(Callback callback, std::function<void()> on_stop)
{
    if (started_.exchange(true)) throw Error("Timer '" + node_id_ + "': start called a second time");
    run(callback, on_stop);
}

void LabTimer::run(const Callback& callback, const std::function<void()>& on_stop)
{
    const RealtimeThread realtime(realtime_, realtime_priority_, "timer '" + node_id_ + "'");
    if (simulated_) {
        run_simulated(callback);
    } else {
        run_real_time(callback);
    }
    // The warnings come at most once a second: the last count is said when the timer ends.
    if (missed_ > missed_reported_) {
        CPM_LOG_WARN("timer '%s': stopped; %llu ticks missed in all", node_id_.c_str(), (unsigned long long)missed_.load());
    }
    if (on_stop) on_stop();
}

void LabTimer::run_simulated(const Callback& callback)
{
    uint64_t next = offset_ns_;  // simulated time starts at 0
    start_time_ = next;
    std::unique_lock<std::mutex> lock(trigger_mutex_);
    uint64_t seen = 0;
    uint64_t announced = UINT64_MAX;  // the tick last announced
    while (!stopping_) {
        // Once per tick: another node's step leaves our announced tick as it was, and the
        // master still has it (and a master that appears late, in the transient-local history).
        if (announced != next) {
            lock.unlock();
            announce(next);
            lock.lock();
            announced = next;
        }
        // Wait for the master to move the clock to our tick (or past it; stop() notifies too).
        // A master that appears late still finds the announcement in the transient-local history.
        wake_at_ = next;
        trigger_changed_.wait(lock, [&] { return stopping_ || trigger_count_ != seen; });
        if (stopping_) break;
        seen = trigger_count_;
        const uint64_t now = next_start_;
        if (now < next) continue;  // another node's tick; ours is still ahead
        if (now > next) {
            // The master passed our tick: it missed our announcement, or the lab's clock was
            // already ahead when this timer joined (a node restarted during a run).
            const uint64_t skipped = (now - next + period_ns_ - 1) / period_ns_;
            missed_ += skipped;
            log_error("timer '" + node_id_ + "': simulated clock jumped to " + std::to_string(now) + " past our tick at " +
                      std::to_string(next) + "; skipped " + std::to_string(skipped) + "; " + std::to_string(missed_.load()) +
                      " ticks missed in all");
            missed_reported_ = missed_;
            next += skipped * period_ns_;
            if (next > now) continue;  // our next tick is still ahead
            // else our tick is the lab's current time: it runs now, or the clock waits for it forever
        }
        // Only a ticking timer moves the process's clock: one whose tick is still ahead may
        // see an older trigger late, and must not wind the clock back under a running tick.
        set_simulated_now(next);
        lock.unlock();
        callback(next);
        lock.lock();
        next += period_ns_;
    }
    lock.unlock();
    // A timer that ends before the lab does (its node is done, or was told to stop) must not
    // hold the simulated clock: it announces that it has no tick left, and the master goes on
    // with the others. Sent before the process can exit with it unsent.
    announce(kStopTrigger);
    (void)ready_writer_->wait_for_acknowledgments(std::chrono::seconds(1));
}

void LabTimer::run_real_time(const Callback& callback)
{
    uint64_t begin = wait_for_start_ ? wait_for_trigger() : get_time_ns();
    if (begin != 0 && !stopping_) {
        begin = std::max(begin, get_time_ns());  // a start already past: join at the next tick
        // The first absolute tick k * period + offset at or after `begin`.
        uint64_t deadline = (begin / period_ns_) * period_ns_ + offset_ns_;
        if (deadline < begin) deadline += period_ns_;
        start_time_ = deadline;
        while (sleep_until(deadline)) {
            callback(deadline);
            deadline += period_ns_;
            const uint64_t now = get_time_ns();
            if (now >= deadline) {
                // Skip every tick that has already passed: no burst of late callbacks.
                const uint64_t skipped = (now - deadline) / period_ns_ + 1;
                missed_ += skipped;
                // A callback that is always too slow overruns every tick: one warning a second.
                uint64_t held = 0;
                if (overrun_log_.allow(now, held)) {
                    CPM_LOG_WARN("timer '%s': the tick at %llu ns ended %.1f ms after its nominal time (slow callback "
                                 "or late wake-up); skipped %llu tick(s); %llu more overrun(s) since the last report, "
                                 "%llu ticks missed in all",
                                 node_id_.c_str(), (unsigned long long)(deadline - period_ns_),
                                 double(now - (deadline - period_ns_)) * 1e-6, (unsigned long long)skipped,
                                 (unsigned long long)held, (unsigned long long)missed_.load());
                    missed_reported_ = missed_;
                }
                deadline += skipped * period_ns_;
            }
        }
    }
}

void LabTimer::start_async(Callback callback, std::function<void()> on_stop)
{
    if (started_.exchange(true)) throw Error("Timer '" + node_id_ + "': start called a second time");
    thread_ = std::thread([this, callback = std::move(callback), on_stop = std::move(on_stop)] {
        try {
            run(callback, on_stop);
        } catch (const std::exception& e) {
            log_error("timer '" + node_id_ + "': callback threw: " + e.what());
        }
    });
}

}  // namespace detail
bool wait_for_inputs(const std::string& node_id, const std::vector<TimerInput>& inputs, const std::function<bool()>& stop_requested)
{
    const auto said_at = std::chrono::steady_clock::now() + std::chrono::seconds(2);
    bool said = false;
    for (;;) {
        std::string missing;
        for (const auto& in : inputs) {
            if (in.matched_writers() == 0) missing += (missing.empty() ? "" : ", ") + in.topic;
        }
        if (missing.empty()) {
            if (said) CPM_LOG_INFO("%s: every input has a writer now; joining the lab clock", node_id.c_str());
            return true;
        }
        if (stop_requested()) return false;
        if (!said && std::chrono::steady_clock::now() >= said_at) {
            CPM_LOG_WARN("%s: waiting for a writer of %s before joining the lab's simulated clock", node_id.c_str(), missing.c_str());
            said = true;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
}

}  // namespace cpm
