#include <cpm/TimeMaster.hpp>

#include "lab_topics.hpp"

#include <cpm/AsyncReader.hpp>
#include <cpm/Error.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>

#include <ReadyStatus.h>
#include <SystemTrigger.h>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <map>
#include <mutex>
#include <optional>

namespace cpm {

using namespace detail;

struct TimeMaster::Impl
{
    explicit Impl(Participant& participant)
        : ready(participant, topics::ready_status.name, topics::ready_status.reader),
          trigger(participant, topics::system_trigger.name, topics::system_trigger.writer),
          live_ready([this](std::vector<ReadyStatus>& r) { on_live(r); }, participant, topics::ready_status.name,
                     live_reader_options(topics::ready_status).on_dds_thread())
    {
    }

    /// One simulated run's state, while run_simulated lasts.
    struct Stepping
    {
        std::vector<std::string> nodes;
        uint64_t end_ns = 0;
        bool started = false, finished = false;
        uint64_t now = 0, steps = 0;
        std::string error;  // a trigger that could not be written
    };

    // Every announcement since the live reader matched, on the DDS thread that delivers it: a
    // step is sent from here, one thread hop less per step than waking the master's thread.
    void on_live(const std::vector<ReadyStatus>& statuses)
    {
        std::lock_guard<std::mutex> lock(mutex);
        for (const auto& r : statuses) merge(r);
        advance();
        // The master's thread is woken to start the clock and when it ended, not for every step.
        if (stepping && (!stepping->started || stepping->finished)) changed.notify_all();
    }
    // The latest announcement of every node. A node's next tick only grows, so the largest
    // value is the latest: Fast DDS was seen delivering an older announcement after a newer one.
    void merge(const ReadyStatus& r)
    {
        uint64_t& t = announced[r.source_id()];
        t = std::max(t, r.next_start_stamp().nanoseconds());
    }
    /// What was announced before the live reader matched (the transient-local reader holds it).
    /// Taken with `lock` released: a writer in this process delivers an announcement inside its
    /// write, holding its own mutex while on_live waits for ours, and a take acknowledges to it.
    void collect(std::unique_lock<std::mutex>& lock)
    {
        lock.unlock();
        auto taken = ready.take();
        lock.lock();
        for (auto& r : taken) merge(r);
    }
    std::vector<std::string> missing(const std::vector<std::string>& nodes) const
    {
        std::vector<std::string> out;
        for (const auto& n : nodes) {
            if (!announced.count(n)) out.push_back(n);
        }
        return out;
    }
    /// The nodes the clock waits for: every node must have announced (before the first step),
    /// then a tick later than the current time (then all ticks at `now` are done); `next` is the
    /// smallest announced.
    std::vector<std::string> waiting_for(uint64_t& next) const
    {
        std::vector<std::string> out;
        next = UINT64_MAX;
        for (const auto& n : stepping->nodes) {
            const auto found = announced.find(n);
            if (found == announced.end() || (stepping->steps > 0 && found->second <= stepping->now)) {
                out.push_back(n);
            } else {
                next = std::min(next, found->second);
            }
        }
        return out;
    }
    /// Moves a started clock on when every node is ahead of it (or ends it).
    void advance()
    {
        if (!stepping || !stepping->started || stepping->finished) return;
        uint64_t next = 0;
        if (!waiting_for(next).empty()) return;
        if (next >= stepping->end_ns) {
            stepping->finished = true;
        } else if (!send(next)) {
            stepping->error = "the SystemTrigger could not be written";
            stepping->finished = true;
        } else {
            stepping->now = next;
            simulated_now = next;
            ++stepping->steps;
        }
    }
    bool send(uint64_t next_start)
    {
        SystemTrigger t;
        t.next_start().nanoseconds(next_start);
        return trigger.write(t);
    }

    ReaderAbstract<ReadyStatus> ready;  ///< what was announced before the live reader matched
    Writer<SystemTrigger> trigger;
    std::mutex mutex;                   ///< guards announced and stepping
    std::condition_variable changed;    ///< the clock may start, or it ended
    std::map<std::string, uint64_t> announced;
    std::optional<Stepping> stepping;
    std::atomic<uint64_t> simulated_now{0};
    /// Every announcement since it matched, volatile writers' too. Last: it goes first, before
    /// what its callback uses.
    AsyncReader<ReadyStatus> live_ready;
};

namespace {

std::string join(const std::vector<std::string>& names)
{
    std::string out;
    for (const auto& n : names) out += (out.empty() ? "'" : ", '") + n + "'";
    return out;
}

}  // namespace

TimeMaster::TimeMaster(Participant& participant) : impl_(std::make_unique<Impl>(participant)) {}

TimeMaster::~TimeMaster() = default;

uint64_t TimeMaster::run_simulated(const std::vector<std::string>& node_ids, uint64_t end_ns,
                                   std::chrono::milliseconds step_timeout, const std::function<void()>& before_start,
                                   std::chrono::milliseconds ready_timeout)
{
    if (node_ids.empty()) throw Error("TimeMaster: no node ids to drive");
    auto& d = *impl_;
    std::unique_lock<std::mutex> lock(d.mutex);
    d.stepping.emplace();
    d.stepping->nodes = node_ids;
    d.stepping->end_ns = end_ns;
    struct Ended  // however it returns: no more steps from the DDS thread
    {
        Impl& d;
        std::unique_lock<std::mutex>& lock;
        ~Ended()
        {
            if (!lock.owns_lock()) lock.lock();
            d.stepping.reset();
        }
    } ended{d, lock};
    auto deadline = std::chrono::steady_clock::now() + ready_timeout;
    uint64_t steps_seen = 0;
    for (;;) {
        d.collect(lock);
        if (!d.stepping->started && d.missing(node_ids).empty()) {
            // Every node has announced: what must be ready runs before the first trigger, while
            // announcements go on arriving (the clock does not move before started is set).
            if (before_start) {
                lock.unlock();
                before_start();
                lock.lock();
                d.collect(lock);
            }
            d.stepping->started = true;
        }
        d.advance();
        if (d.stepping->finished) break;
        if (d.stepping->steps != steps_seen) {
            steps_seen = d.stepping->steps;
            deadline = std::chrono::steady_clock::now() + step_timeout;
        }
        const auto remaining = deadline - std::chrono::steady_clock::now();
        if (remaining <= std::chrono::steady_clock::duration::zero()) {
            if (!d.stepping->started) {
                throw Error("TimeMaster: simulated time not started within " + std::to_string(ready_timeout.count()) +
                            " ms: no announcement from " + join(d.missing(node_ids)));
            }
            uint64_t next = 0;
            throw Error("TimeMaster: simulated time stuck at " + std::to_string(d.stepping->now) + " ns: no announcement from " +
                        join(d.waiting_for(next)) + " within " + std::to_string(step_timeout.count()) + " ms");
        }
        // The steps are made on the DDS thread; this one looks, in short slices, at what only the
        // transient-local reader holds and at the time each step takes.
        d.changed.wait_for(lock, std::min(std::chrono::duration_cast<std::chrono::milliseconds>(remaining) +
                                              std::chrono::milliseconds(1),
                                          std::chrono::milliseconds(10)));
    }
    const std::string error = d.stepping->error;
    const uint64_t steps = d.stepping->steps;
    lock.unlock();
    if (!error.empty()) throw Error("TimeMaster: " + error);
    stop_all();
    return steps;
}

uint64_t TimeMaster::start_real_time(const std::vector<std::string>& node_ids, std::chrono::milliseconds start_delay,
                                     std::chrono::milliseconds ready_timeout)
{
    auto& d = *impl_;
    const auto deadline = std::chrono::steady_clock::now() + ready_timeout;
    std::unique_lock<std::mutex> lock(d.mutex);
    for (d.collect(lock); !d.missing(node_ids).empty(); d.collect(lock)) {
        if (std::chrono::steady_clock::now() >= deadline) {
            throw Error("TimeMaster: not ready within " + std::to_string(ready_timeout.count()) +
                        " ms: " + join(d.missing(node_ids)));
        }
        d.changed.wait_for(lock, std::chrono::milliseconds(20));
    }
    lock.unlock();
    const uint64_t start = get_time_ns() + static_cast<uint64_t>(start_delay.count()) * 1'000'000ull;
    if (!d.send(start)) throw Error("TimeMaster: the SystemTrigger could not be written");
    return start;
}

uint64_t TimeMaster::simulated_now() const { return impl_->simulated_now; }

void TimeMaster::stop_all()
{
    if (!impl_->send(kStopTrigger)) throw Error("TimeMaster: the SystemTrigger could not be written");
    // A master that ends right after the stop must not take it along unsent.
    impl_->trigger.wait_for_acknowledgments(std::chrono::seconds(2));
}

}  // namespace cpm
