#pragma once
// The dash-cam save: a new recording of what the live history holds around a moment, the
// KogMo-RTDB ring put on disk. It starts with the samples the store holds of the span, then
// takes the live ingest's (it is a sink of the Outlet meanwhile) until the span's end has
// passed, so that nothing between the two is lost or doubled, and the service never stops.
#include <cpm/rtdb/HistoryService.hpp>
#include <cpm/rtdb/IngestSink.hpp>
#include <cpm/rtdb/Recording.hpp>
#include <cpm/rtdb/Store.hpp>

#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <vector>

namespace cpm::rtdb {

struct SaveSpan
{
    std::string path;               ///< the new file (.mcap: MCAP, else SQLite)
    std::set<std::string> topics;   ///< none: every topic
    uint64_t from_ns = 0, to_ns = 0;  ///< the samples of data time in [from, to)
    std::string name;               ///< the recording's name (its meta)
};

struct SaveResult
{
    std::string path;
    uint64_t samples = 0, objects = 0;
    std::string error;  ///< "" when the file was written whole
};

class Save final : public IngestSink
{
public:
    /// Creates the file; throws cpm::Error naming it when it cannot (it exists, no folder).
    explicit Save(SaveSpan span);
    /// Under the ingest's lock, before the Save becomes a sink: every object of its topics and
    /// their held samples of the span, in commit order.
    void start(const Store& store);
    void object_added(const ObjectInfo& info) override;
    void sample_committed(Oid oid, const Incoming& sample, uint64_t commit_ns) override;
    void object_deleted(Oid oid, uint64_t deleted_ns) override;
    /// Off the lock, once it is no sink any more: closes the file.
    SaveResult finish();
    const SaveSpan& span() const { return span_; }

private:
    bool wanted(const std::string& topic) const { return span_.topics.empty() || span_.topics.count(topic); }
    SaveSpan span_;
    std::unique_ptr<RecordingWriter> writer_;
    std::set<Oid> oids_;  // the objects it records
};

/// Watches the ingest for the samples of --save-on triggers and hands each on: every sample of
/// a trigger without a filter, and for one with a filter the sample with which an object begins
/// to match it (keep `fire` short: it runs under the ingest's lock).
class TriggerSink final : public IngestSink
{
public:
    struct Fired
    {
        size_t trigger = 0;  ///< its index in the options
        std::string key;     ///< the sample's object's key
        uint64_t commit_ns = 0;
        uint64_t data_ns = 0;  ///< the trigger sample's data time: the span is around it
    };
    TriggerSink(std::vector<SaveTrigger> triggers, std::function<void(const Fired&)> fire);
    void object_added(const ObjectInfo& info) override;
    void sample_committed(Oid oid, const Incoming& sample, uint64_t commit_ns) override;
    void object_deleted(Oid, uint64_t) override {}

private:
    std::vector<SaveTrigger> triggers_;
    std::function<void(const Fired&)> fire_;
    std::map<Oid, std::pair<std::string, std::string>> objects_;  // of a trigger's topic: type, key
    std::map<std::pair<size_t, Oid>, bool> matching_;              // a filter's last verdict per object
};

}  // namespace cpm::rtdb
