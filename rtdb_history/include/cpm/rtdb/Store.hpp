#pragma once
// cpm::rtdb — the KogMo-RTDB style time-indexed store (docs/design.md), usable in-process.
//
// An object is one instance (topic + key) of a topic, or a process (participant). Each stored
// sample keeps its commit time (when the store received it; strictly increasing per object, a
// tie gets +1 ns), its data time (create_stamp), valid_after_stamp, the writer's source
// timestamp and the payload bytes as received. Both times are indexed.
//
// Data time need not be monotone. Data-time queries answer over the samples held, ordered by
// (data time, commit time): "at" is the held sample with the greatest data time <= t (among
// equal data times the one committed last), "older"/"younger" the greatest below / smallest
// above t, "range" lists in data-time order. When no held sample qualifies the answer says
// why: not_found when t lies before every data time ever stored for the object, evicted when
// samples at or before t were stored but are gone (out of the window), not_yet when asking
// past the newest.
//
// Concurrency: one ingest path (add_object/commit/mark_deleted/expire), any number of readers.
// Readers find an object's slot without a lock and take only that object's reader lock; they
// copy what they return under it (or see it in place, view()), so they never see a torn sample.
// snapshot() holds every asked object's lock at once, so no commit can slip in between its
// answers.
#include <cpm/HistoryVocabulary.hpp>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <shared_mutex>
#include <utility>
#include <string>
#include <type_traits>
#include <vector>

namespace cpm::rtdb {

using Oid = uint64_t;
constexpr Oid kNoOid = 0;

// The history's vocabulary (cpm/HistoryVocabulary.hpp), one spelling for C++, wire and JSON.
using Status = cpm::history::Status;
using By = cpm::history::By;
using cpm::history::to_string;

struct StoredSample
{
    uint64_t commit_ns = 0;
    uint64_t data_ns = 0;         ///< create_stamp
    uint64_t valid_after_ns = 0;  ///< valid_after_stamp
    uint64_t source_ns = 0;       ///< the writer's source timestamp (0 if unknown)
    std::vector<uint8_t> payload; ///< serialized as received
};

/// A held sample seen in place: the times and the payload bytes inside the store, valid only
/// while the visitor that received it runs (the object's lock is held meanwhile, so it is never
/// torn; keep the visitor short, the ingest of that object waits for it).
struct SampleView
{
    uint64_t commit_ns = 0;
    uint64_t data_ns = 0;
    uint64_t valid_after_ns = 0;
    uint64_t source_ns = 0;
    const uint8_t* data = nullptr;
    size_t size = 0;
};

/// The single-sample queries.
enum class Which { latest, at, older, younger };

struct Found
{
    Status status = Status::not_found;
    StoredSample sample;  ///< meaningful when status == ok
    bool ok() const { return status == Status::ok; }
};

struct Range
{
    Status status = Status::not_found;
    std::vector<StoredSample> samples;
    bool truncated = false;  ///< more matched than the limit
    uint64_t lost = 0;       ///< samples the store never got between the first and the last returned
};

/// What a new sample brings; the payload is copied.
struct Incoming
{
    uint64_t data_ns = 0;
    uint64_t valid_after_ns = 0;
    uint64_t source_ns = 0;
    const uint8_t* data = nullptr;
    size_t size = 0;
    /// Samples its writer sent before this one that never arrived (a gap in its sequence
    /// numbers): successor() of the sample before it answers gap, and they are counted.
    uint64_t lost_before = 0;
};

enum class ObjectKind { instance, process };

/// The info block of an object (docs/design.md).
struct ObjectInfo
{
    Oid oid = kNoOid;
    ObjectKind kind = ObjectKind::instance;
    std::string name;      ///< "topic", "topic/key" or, for a process, the participant's name
    std::string topic;     ///< empty for processes
    std::string key;       ///< the instance key as text (the vehicle id), empty if unkeyed
    std::string type_name; ///< the DDS type name; "participant" for processes
    Oid parent = kNoOid;   ///< the creating process's object, if known
    std::string creator;   ///< creating participant's name
    std::string creator_guid;
    uint64_t created_ts = 0;
    uint64_t deleted_ts = 0;  ///< 0 while alive
    uint64_t history_interval_ns = 0;
    /// Where the data time comes from: "create_stamp" (the sample's Header) or, for a type
    /// without a Header, "source_timestamp" (the writer's, as DDS delivered it).
    std::string data_time = "create_stamp";
    // Filled in by info()/search():
    uint64_t samples_held = 0;
    uint64_t bytes_held = 0;
    uint64_t samples_total = 0;     ///< ever committed
    uint64_t samples_lost = 0;      ///< ever sent by its writers and never received (Incoming::lost_before)
    uint64_t newest_commit_ns = 0;
    uint64_t oldest_commit_ns = 0;  ///< of the samples held
    double avg_cycle_s = 0;         ///< observed mean time between commits
    double max_cycle_s = 0;
};

/// Object search: the AND of the criteria given.
struct Criteria
{
    std::optional<std::string> name_regex;  ///< ECMAScript, case-insensitive, searched within the name
    std::optional<std::string> type_name;
    std::optional<Oid> parent;
    std::optional<std::string> creator;     ///< participant name or GUID
    std::optional<uint64_t> alive_at;       ///< created at or before and not deleted by then
    std::optional<ObjectKind> kind;
};

struct Retention
{
    uint64_t window_ns = 10'000'000'000ull;  ///< history_interval
    uint64_t max_bytes_per_topic = 64ull << 20;  ///< payload bytes of one topic
};

struct StoreOptions
{
    Retention default_retention;
    uint64_t max_bytes_total = 512ull << 20;  ///< payload bytes across all topics
};

struct StoreStats
{
    uint64_t objects = 0, alive = 0, samples = 0, bytes = 0, evicted = 0, purged_objects = 0, lost = 0;
};

/// What changed since a point: objects created or deleted after it.
struct Changes
{
    std::vector<ObjectInfo> created;
    std::vector<ObjectInfo> deleted;
};

class Store
{
public:
    explicit Store(StoreOptions options = {});
    ~Store();
    Store(const Store&) = delete;
    Store& operator=(const Store&) = delete;

    /// Retention of one topic (objects created afterwards and those already there).
    void set_retention(const std::string& topic, Retention r);
    Retention retention(const std::string& topic) const;

    // ---- ingest (one thread) ------------------------------------------------------------
    /// Registers an object; info.oid, created_ts (if 0: now) and history_interval are filled
    /// in. Returns the new oid.
    Oid add_object(ObjectInfo info);
    /// Puts an object back under the oid it had (a recording being loaded): info.oid,
    /// created_ts and history_interval_ns are kept as given, while the store keeps its samples
    /// by its own retention. Returns the oid it got: the one given, or a new one when that
    /// oid's slot holds another object already (the live store had purged the older one and
    /// given its slot to this one).
    Oid restore_object(ObjectInfo info);
    /// Stores a sample; returns its commit time (max(now_ns, previous + 1)).
    uint64_t commit(Oid oid, const Incoming& in, uint64_t now_ns);
    /// Marks an object deleted at t: it stays readable for its history_interval, then expire()
    /// purges it.
    void mark_deleted(Oid oid, uint64_t t_ns);
    /// Evicts samples older than each topic's window and purges deleted objects whose window
    /// has passed. Call it periodically (the service does, 10 times a second).
    void expire(uint64_t now_ns);

    // ---- queries (any thread) -----------------------------------------------------------
    Found latest(Oid oid) const;
    Found at(Oid oid, uint64_t t, By by = By::commit) const;
    Found older(Oid oid, uint64_t t, By by = By::commit) const;
    Found younger(Oid oid, uint64_t t, By by = By::commit) const;
    /// The same queries without copying: f(const SampleView&) runs on the sample in place
    /// (only when the status is ok), like sqlite3_column_blob's pointer. t is ignored for
    /// Which::latest.
    template <typename F>
    Status view(Oid oid, Which which, uint64_t t, By by, F&& f) const
    {
        return view_with(oid, which, t, by, [](void* fp, const SampleView& v) { (*static_cast<std::remove_reference_t<F>*>(fp))(v); },
                         const_cast<void*>(static_cast<const void*>(&f)));
    }
    /// Samples with time in [t0, t1), oldest first, at most `limit`.
    Range range(Oid oid, uint64_t t0, uint64_t t1, By by = By::commit, size_t limit = 10000) const;
    /// The newest sample committed after `after`, waiting up to `timeout` for one.
    Found wait_next(Oid oid, uint64_t after, std::chrono::nanoseconds timeout) const;
    /// Exactly the sample committed next after `after` (waiting up to `timeout`), or gap when
    /// it was evicted or samples were lost in between.
    Found successor(Oid oid, uint64_t after, std::chrono::nanoseconds timeout) const;
    /// Each object's sample at t, in one consistent cut.
    std::vector<Found> snapshot(uint64_t t, const std::vector<Oid>& oids, By by = By::commit) const;

    // ---- registry -----------------------------------------------------------------------
    std::optional<ObjectInfo> info(Oid oid) const;
    /// Objects (alive, or deleted and still held) matching all criteria, by oid.
    /// Throws cpm::Error naming a name_regex that is not a regular expression.
    std::vector<ObjectInfo> search(const Criteria& c) const;
    /// Waits up to `timeout` for a matching object to exist.
    std::optional<ObjectInfo> wait_for_object(const Criteria& c, std::chrono::nanoseconds timeout) const;
    /// The object of topic + key, if held (not purged): the newest of that name.
    std::optional<Oid> find(const std::string& topic, const std::string& key) const;
    /// Every object of topic + key held, oldest first: more than one when its writer was
    /// marked dead and a writer of the same instance came after (a restarted process).
    std::vector<Oid> named(const std::string& topic, const std::string& key) const;
    Changes changes_since(uint64_t t_ns) const;
    StoreStats stats() const;

private:
    struct Object;
    /// The object in oid's slot, whichever oid it holds now (nullptr if the slot was never used).
    Object* slot(Oid oid) const;
    /// The object of oid if it is held; ingest thread only (only it changes what a slot holds).
    Object* live(Oid oid) const;
    /// Every slot's object, held or free.
    std::vector<Object*> slots() const;
    /// Runs f(const Object*) (nullptr if unknown or purged) under the object's shared lock.
    template <typename F>
    auto read(Oid oid, F&& f) const;
    Status view_with(Oid oid, Which which, uint64_t t, By by, void (*fn)(void*, const SampleView&), void* ctx) const;
    Found copy_of(Oid oid, Which which, uint64_t t, By by) const;
    static Range range_of(const Object& o, uint64_t t0, uint64_t t1, By by, size_t limit);
    // Eviction (ingest thread; the object's lock held, except evict_for_budget, which locks).
    void evict_oldest(Object& o);
    void evict_window(Object& o, uint64_t newest);
    void evict_for_budget(Object& o, uint64_t needed);
    void notify();
    /// Calls attempt() until it returns true, waiting for the store to change between tries;
    /// false when the timeout passed first.
    bool retry_on_change(std::chrono::nanoseconds timeout, const std::function<bool()>& attempt) const;
    Found wait_for(Oid oid, uint64_t after, std::chrono::nanoseconds timeout, bool exact) const;

    StoreOptions options_;
    // Objects live in slots that readers find without a lock: an oid is generation << 32 | slot;
    // a purged object's slot is given to a later one with the next generation, so a reader
    // holding an old oid finds the slot's oid changed. Slot objects are freed with the store.
    static constexpr unsigned kBlockBits = 10;
    static constexpr uint32_t kBlockMask = (1u << kBlockBits) - 1;  ///< a slot's place in its block
    static constexpr size_t kBlocks = 4096;  ///< at most 4M objects held at once
    Object** blocks_[kBlocks] = {};          ///< written before slots_used_ grows past them
    std::atomic<uint32_t> slots_used_{1};    ///< slot 0 is none
    mutable std::shared_mutex registry_mutex_;  ///< add_object and purge; guards the maps below
    std::vector<uint32_t> free_slots_;
    std::map<std::string, Retention> retention_;
    std::map<std::string, uint64_t> topic_bytes_;  ///< objects point at their topic's node
    std::map<std::pair<std::string, std::string>, std::vector<Oid>> by_name_;  ///< topic and key: its instance objects, oldest first
    uint64_t total_bytes_ = 0;
    std::atomic<uint64_t> evicted_{0}, purged_{0}, lost_{0};

    mutable std::mutex wait_mutex_;
    mutable std::condition_variable wait_cv_;
    mutable int waiters_ = 0;
    uint64_t version_ = 0;  ///< under wait_mutex_: bumped on every change a waiter may want
};

}  // namespace cpm::rtdb
