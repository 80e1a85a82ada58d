#include <cpm/TimeMaster.hpp>

#include "lab_topics.hpp"

#include <cpm/Error.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>

#include <ReadyStatus.h>
#include <SystemTrigger.h>

#include <algorithm>
#include <atomic>
#include <map>

namespace cpm {

using namespace detail;

struct TimeMaster::Impl
{
    explicit Impl(Participant& participant)
        : ready(participant, topics::ready_status.name, topics::ready_status.reader),
          live_ready(participant, topics::ready_status.name, live_reader_options(topics::ready_status)),
          trigger(participant, topics::system_trigger.name, topics::system_trigger.writer)
    {
    }

    // The latest announcement of every node. A node's next tick only grows, so the largest
    // value is the latest: Fast DDS was seen delivering an older announcement after a newer one.
    void collect()
    {
        for (auto* reader : {&ready, &live_ready}) {
            for (auto& r : reader->take()) {
                uint64_t& t = announced[r.source_id()];
                t = std::max(t, r.next_start_stamp().nanoseconds());
            }
        }
    }
    std::vector<std::string> missing(const std::vector<std::string>& nodes) const
    {
        std::vector<std::string> out;
        for (const auto& n : nodes) {
            if (!announced.count(n)) out.push_back(n);
        }
        return out;
    }
    void send(uint64_t next_start)
    {
        SystemTrigger t;
        t.next_start().nanoseconds(next_start);
        if (!trigger.write(t)) throw Error("TimeMaster: the SystemTrigger could not be written");
    }

    ReaderAbstract<ReadyStatus> ready;       ///< what was announced before it matched
    ReaderAbstract<ReadyStatus> live_ready;  ///< every announcement since, volatile writers' too
    Writer<SystemTrigger> trigger;
    std::map<std::string, uint64_t> announced;
    std::atomic<uint64_t> simulated_now{0};
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
    bool started = false;
    uint64_t now = 0, steps = 0;
    auto deadline = std::chrono::steady_clock::now() + ready_timeout;
    for (;;) {
        impl_->collect();
        // Every node must have announced a tick later than the current time: then all ticks
        // at `now` are done, and the next time is the smallest announced one.
        std::vector<std::string> waiting_for;
        uint64_t next = UINT64_MAX;
        for (const auto& n : node_ids) {
            const auto found = impl_->announced.find(n);
            if (found == impl_->announced.end() || (started && found->second <= now)) {
                waiting_for.push_back(n);
            } else {
                next = std::min(next, found->second);
            }
        }
        if (waiting_for.empty()) {
            if (!started && before_start) before_start();
            if (next >= end_ns) {
                stop_all();
                return steps;
            }
            impl_->send(next);
            now = next;
            impl_->simulated_now = now;
            started = true;
            ++steps;
            deadline = std::chrono::steady_clock::now() + step_timeout;
            continue;
        }
        const auto remaining = deadline - std::chrono::steady_clock::now();
        if (remaining <= std::chrono::steady_clock::duration::zero()) {
            if (!started) {
                throw Error("TimeMaster: simulated time not started within " + std::to_string(ready_timeout.count()) +
                            " ms: no announcement from " + join(waiting_for));
            }
            throw Error("TimeMaster: simulated time stuck at " + std::to_string(now) + " ns: no announcement from " +
                        join(waiting_for) + " within " + std::to_string(step_timeout.count()) + " ms");
        }
        // Every announcement comes to the live reader, except those sent before it matched,
        // which only the transient-local one holds: wait on the live one, in short slices.
        (void)impl_->live_ready.wait_for_data(std::min(std::chrono::duration_cast<std::chrono::milliseconds>(remaining) +
                                                     std::chrono::milliseconds(1),
                                                 std::chrono::milliseconds(10)));
    }
}

uint64_t TimeMaster::start_real_time(const std::vector<std::string>& node_ids, std::chrono::milliseconds start_delay,
                                     std::chrono::milliseconds ready_timeout)
{
    const auto deadline = std::chrono::steady_clock::now() + ready_timeout;
    for (impl_->collect(); !impl_->missing(node_ids).empty(); impl_->collect()) {
        if (std::chrono::steady_clock::now() >= deadline) {
            throw Error("TimeMaster: not ready within " + std::to_string(ready_timeout.count()) +
                        " ms: " + join(impl_->missing(node_ids)));
        }
        (void)impl_->live_ready.wait_for_data(std::chrono::milliseconds(20));
    }
    const uint64_t start = get_time_ns() + static_cast<uint64_t>(start_delay.count()) * 1'000'000ull;
    impl_->send(start);
    return start;
}

uint64_t TimeMaster::simulated_now() const { return impl_->simulated_now; }

void TimeMaster::stop_all()
{
    impl_->send(kStopTrigger);
    // A master that ends right after the stop must not take it along unsent.
    impl_->trigger.wait_for_acknowledgments(std::chrono::seconds(2));
}

}  // namespace cpm
