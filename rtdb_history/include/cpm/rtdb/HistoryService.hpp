#pragma once
// cpm_history as a library: finds topics by DDS discovery, records every matching one into a
// Store as raw serialized payloads (types it was never compiled with included), answers
// historyRequest with historyReply and publishes historyStatus.
#include <cpm/Participant.hpp>
#include <cpm/rtdb/IngestSink.hpp>
#include <cpm/rtdb/Store.hpp>

#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace cpm::rtdb {

/// `--save-on TOPIC[=FIELD==VALUE]`: a sample on TOPIC (whose field, by IDL path, has that value;
/// != for another value) saves the span around it by itself, as `cpm history save` does.
struct SaveTrigger
{
    std::string topic;
    std::string field;  ///< "" for any sample
    std::string value;
    bool equal = true;
    std::string text;   ///< as given
};

/// Reads a --save-on value; throws cpm::cli::UsageError naming what does not parse.
SaveTrigger parse_save_trigger(const std::string& text);

/// The participant a history service of that name (its node id; "" for cpm_history's) records
/// through: "<service>_recorder". Others find its readers by it (cpm lab run's clock waits for them).
inline std::string recorder_name(const std::string& service)
{
    return (service.empty() ? std::string("cpm_history") : service) + "_recorder";
}

struct ServiceOptions
{
    std::vector<std::string> include;  ///< topic name regexes (full match); empty: every topic
    std::vector<std::string> exclude;  ///< topic name regexes never recorded (historyRequest/Reply always are)
    uint64_t window_ns = 10'000'000'000ull;
    uint64_t max_bytes_total = 512ull << 20;      ///< payload bytes across all topics
    uint64_t max_bytes_per_topic = 128ull << 20;  ///< payload bytes of one topic
    std::map<std::string, uint64_t> topic_windows_ns;  ///< topics keeping another window than window_ns
    uint64_t status_period_ns = 1'000'000'000ull;
    size_t workers = 4;  ///< threads answering requests that may wait
    /// Unset: requests, replies and status go through the process's default participant (the one
    /// cpm::init's settings make, which cpm::Logging uses too), so the process shows as one
    /// participant of its name besides its recorder. Set: a participant of these options.
    /// After the process stood still for nearly its lease (SIGSTOP, a debugger), the service
    /// makes its participants anew (then one of its own even when unset), so that the others,
    /// which dropped it meanwhile, meet it afresh.
    std::optional<ParticipantOptions> participant;
    /// Beside the store, these get every object, sample and deletion the service records.
    std::vector<std::shared_ptr<IngestSink>> sinks;
    /// Where `save` requests (cpm history save) write their recordings: a file name of the
    /// request's in this folder, never a path of the requester's. "": the working directory.
    std::string save_dir;
    /// Saves by themselves: each trigger's file is save_<UTC time>_<topic>[_<key>].db (.mcap
    /// with save_format "mcap") in save_dir, [trigger - save_before_ns, trigger + save_after_ns).
    std::vector<SaveTrigger> save_on;
    uint64_t save_before_ns = 30'000'000'000ull, save_after_ns = 10'000'000'000ull;
    std::string save_format = "sqlite";
    /// Not "": the service joins the lab's simulated clock as this node, ticking every
    /// clock_period_ns of lab time (1 ms into it, in the simulated cars' step: a step of its own
    /// only where no car ticks), and each tick waits until every other node's announcement of
    /// a tick at or after it has reached the recorder: all the nodes wrote before is then
    /// recorded, so a clock that runs faster than the recorder can take (a busy machine, a
    /// paused process) is held back instead of the recording losing samples. The service's own
    /// clock (commit times, its window) stays the wall clock.
    std::string clock_node;
    uint64_t clock_period_ns = 100'000'000ull;
};

struct ServiceCounters
{
    uint64_t topics = 0, received = 0, dropped = 0, requests = 0, bad_requests = 0, lost = 0;
    std::map<std::string, uint64_t> lost_by_topic;  ///< the topics that lost samples (lost, per topic)
};

class HistoryService
{
public:
    /// Starts recording and serving at once. Throws cpm::Error for a bad pattern or when DDS
    /// refuses the participants.
    explicit HistoryService(ServiceOptions options);
    ~HistoryService();
    HistoryService(const HistoryService&) = delete;
    HistoryService& operator=(const HistoryService&) = delete;

    const Store& store() const;
    ServiceCounters counters() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm::rtdb
