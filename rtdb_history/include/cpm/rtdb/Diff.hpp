#pragma once
// Two recordings compared sample for sample: what `cpm history --file A diff B` reports, and
// what a test of a simulated run's repeatability asserts.
#include <cpm/rtdb/Recording.hpp>
#include <cpm/topics.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace cpm::rtdb {

/// What diff_recordings compares.
struct DiffOptions
{
    std::vector<std::string> topics;  ///< none: every topic either holds
    /// Topics left out: by default the lab clock's own traffic (its ready announcements and
    /// triggers, which carry each process's wall clock) and the log (its texts name processes'
    /// ids and wall-clock times) and the history service's status (its own wall clock).
    std::vector<std::string> exclude{topics::ready_status.name, topics::system_trigger.name, topics::log.name,
                                     topics::history_status.name};
};

/// The first difference of one topic and key.
struct SampleDifference
{
    std::string topic;
    std::string key;          ///< "" for an unkeyed topic
    uint64_t index = 0;       ///< the sample, counted from 0 in data-time order
    uint64_t data_ns_a = 0;   ///< its data time in A (0: A has no such sample)
    uint64_t data_ns_b = 0;
    /// What differs: "only in A (B has no vehicleState/5)", "A has 2000 samples, B 1998",
    /// "data time 1.240000000 s in A, 1.260000000 s in B", "pose.x: 1.25 in A, 1.2500001 in B".
    std::string what;
};

struct DiffResult
{
    uint64_t objects = 0;   ///< topic/key pairs compared
    uint64_t samples = 0;   ///< samples compared that were equal
    std::vector<SampleDifference> differences;  ///< by topic, then key
    bool identical() const { return differences.empty(); }
};

/// Compares each topic and key's samples by data time and payload bytes (commit times, the
/// recorder's own clock, never match between two runs). Samples of one key with the same data
/// time are taken in payload order, so arrival order does not count. A payload that differs is
/// decoded (with A's types) to name its first field that differs.
DiffResult diff_recordings(const LoadedRecording& a, const LoadedRecording& b, const DiffOptions& options = {});

}  // namespace cpm::rtdb
