#pragma once
#include <chrono>
#include <functional>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <cpm/Participant.hpp>

namespace cpm {

/// The lab's clock master: starts and stops every cpm::Timer through `systemTrigger`.
///
/// Simulated time: every timer announces the nominal time of its next tick in
/// `ReadyStatus.next_start_stamp`; the master advances the lab clock to the smallest announced
/// time, but only once every node has announced a time later than the current one (so all
/// ticks at t finish before anything at t' > t runs). Runs are therefore repeatable and run as
/// fast as the nodes compute. A timer that ends early announces UINT64_MAX (no tick left); the
/// clock goes on with the others. Real time: one synchronised start, later a stop.
class TimeMaster
{
public:
    explicit TimeMaster(Participant& participant);
    ~TimeMaster();
    TimeMaster(const TimeMaster&) = delete;
    TimeMaster& operator=(const TimeMaster&) = delete;

    /// Drives simulated time for the named nodes from 0 until `end_ns`, then stops all timers.
    /// Waits up to `ready_timeout` for every node's first announcement (processes still
    /// starting, on other hosts too), then up to `step_timeout` for each step; throws cpm::Error
    /// naming the silent nodes when either runs out. Returns the number of steps (distinct tick
    /// times) it triggered. `before_start` (if given) runs once every node has announced, before
    /// the first trigger: what must be ready before lab time moves (cpm lab run: the recorder
    /// reading every writer).
    uint64_t run_simulated(const std::vector<std::string>& node_ids, uint64_t end_ns,
                           std::chrono::milliseconds step_timeout = std::chrono::seconds(10),
                           const std::function<void()>& before_start = {},
                           std::chrono::milliseconds ready_timeout = std::chrono::seconds(30));

    /// The simulated time run_simulated last triggered (0 before); safe from any thread.
    uint64_t simulated_now() const;

    /// Real time: waits until the named nodes are ready (or `ready_timeout`; throws naming the
    /// missing ones), then sends the start `start_delay` from now. Returns the start time.
    uint64_t start_real_time(const std::vector<std::string>& node_ids,
                             std::chrono::milliseconds start_delay = std::chrono::seconds(1),
                             std::chrono::milliseconds ready_timeout = std::chrono::seconds(30));

    /// Stops every timer in the lab (SystemTrigger UINT64_MAX); waits up to 2 s until the
    /// timers' readers acknowledged it.
    void stop_all();

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm
