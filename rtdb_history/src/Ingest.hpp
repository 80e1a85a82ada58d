#pragma once
// The history service's ingest: a recording participant that finds writers by discovery,
// opens a raw reader per wanted topic, and hands every sample — with its object from the
// registry, its data time and the writer's sequence gaps — to the outlet. Discovery is
// handled on the caller's thread (process_events), never in a Fast DDS callback.
#include <cpm/Participant.hpp>
#include <cpm/rtdb/HistoryService.hpp>

#include "Outlet.hpp"
#include "Registry.hpp"

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <memory>
#include <mutex>
#include <regex>
#include <string>
#include <vector>

namespace cpm::rtdb {

/// A recorded topic as the status reports it.
struct TopicCount
{
    std::string topic, type_name;
    uint64_t received = 0, lost = 0;
};

class Ingest
{
public:
    /// Starts the recording participant (named after `participant`'s name + "_recorder").
    /// Throws cpm::Error for a bad include/exclude pattern or when DDS refuses.
    Ingest(const ServiceOptions& options, Outlet& out);
    ~Ingest();
    Ingest(const Ingest&) = delete;
    Ingest& operator=(const Ingest&) = delete;

    /// Handles what discovery reported, waiting up to `wait` for something; false once stop()
    /// was called.
    bool process_events(std::chrono::milliseconds wait);
    void stop();
    /// Runs f under the ingest's lock (nothing is committed meanwhile).
    template <class F>
    auto locked(F&& f)
    {
        std::lock_guard lock(mutex_);
        return f();
    }

    /// Replaces the recording participant with a new one (see Ingest.cpp); on the caller's
    /// thread, not in a DDS callback.
    void rebuild();
    /// With ServiceOptions::clock_node: waits up to `timeout` until every other node of the
    /// lab's simulated clock has announced to the recording participant a tick at or after
    /// `t_ns` (all it wrote before has then reached the recorder). Returns the nodes still behind,
    /// which are not waited for again until they announce anew; empty once stop() was called.
    std::vector<std::string> wait_for_clock(uint64_t t_ns, std::chrono::milliseconds timeout);
    /// Whether a reader records this topic.
    bool records(const std::string& topic) const;

    uint64_t received() const { return received_; }
    uint64_t dropped() const { return dropped_; }
    uint64_t lost() const { return lost_; }
    size_t topic_count() const;
    std::vector<TopicCount> topic_counts() const;
    /// Samples received on one topic (0 if it has none).
    uint64_t received(const std::string& topic) const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
    mutable std::mutex mutex_;  ///< the ingest path: reader callbacks, registry, expiry
    std::atomic<uint64_t> received_{0}, dropped_{0}, lost_{0};
};

}  // namespace cpm::rtdb
