#pragma once
// What the store (Store.cpp) holds of one object: its samples' records by commit time, its
// data-time index, their payload bytes and the counters info() reports.
#include <cpm/rtdb/Store.hpp>

#include "ByteChunks.hpp"
#include "Ring.hpp"

#include <algorithm>
#include <cstdint>
#include <deque>
#include <limits>
#include <utility>

namespace cpm::rtdb::detail {

constexpr uint64_t kNever = std::numeric_limits<uint64_t>::max();

/// A sample's times and its payload's address in the object's chunks (which never move): 44
/// bytes. Holding the address, not a chunk number, spares a query the walk to the chunk.
#pragma pack(push, 4)
struct Record
{
    uint64_t commit, data, valid_after, source;
    const uint8_t* payload;
    uint32_t size;
};
#pragma pack(pop)
static_assert(sizeof(Record) == 44);

/// Where a search of n sorted keys first looks for t: by interpolation between the first and the
/// last key. Kept up to date by the writer, so that a query's first probe waits neither for
/// both ends' keys nor for a division; it only steers that probe, so a stale one costs time,
/// never a wrong answer.
struct Spread
{
    uint64_t first = 0;
    double per_ns = 0;  ///< (n - 1) / (last - first)

    static Spread of(size_t n, uint64_t first, uint64_t last) { return {first, last > first ? double(n - 1) / double(last - first) : 0.0}; }
    /// The interpolated index of t, at most `max`.
    size_t guess(uint64_t t, size_t max) const { return size_t(std::min(double(t - std::min(t, first)) * per_ns, double(max))); }
};

/// Index of the first of n sorted keys with key > t (inclusive) or >= t (!inclusive); n if none.
/// Samples mostly come periodically, so it first probes at `first_probe` (the caller's guess by
/// interpolation, Spread::guess) and then gallops out from there: a few neighbouring probes
/// instead of log2(n) scattered cache misses; O(log n) at worst, whatever the guess.
template <typename Key>
size_t search_sorted(size_t n, Key key, uint64_t t, bool inclusive, size_t first_probe)
{
    auto left_of = [&](size_t i) { return inclusive ? key(i) <= t : key(i) < t; };  // the answer is right of i
    if (n == 0 || !left_of(0)) return 0;
    if (left_of(n - 1)) return n;
    // Now key(0) is left of the answer and key(n - 1) is not: the answer is in (0, n - 1].
    const size_t guess = std::min(first_probe, n - 2);
    size_t lo, hi;  // left_of(lo) holds, left_of(hi) does not
    if (left_of(guess)) {
        lo = guess;
        size_t step = 1;
        while (lo + step < n - 1 && left_of(lo + step)) {
            lo += step;
            step *= 2;
        }
        hi = std::min(n - 1, lo + step);
    } else {
        hi = guess;
        size_t step = 1;
        while (hi >= step && !left_of(hi - step)) {
            hi -= step;
            step *= 2;
        }
        lo = hi >= step ? hi - step : 0;
    }
    while (hi - lo > 1) {
        const size_t mid = lo + (hi - lo) / 2;
        (left_of(mid) ? lo : hi) = mid;
    }
    return hi;
}

/// What the store holds of one object; Store::Object adds its lock. A purged object's state is
/// reset to this (its memory given back) and its slot taken by the next new object. Not
/// thread-safe: the caller holds the object's lock (shared for the const members). The members
/// a commit or a query runs are defined here, to be inlined; the rest in ObjectState.cpp.
struct ObjectState
{
    ObjectInfo info;  // deleted_ts and the counters change under mutex
    Retention retention;
    uint64_t* topic_bytes = nullptr;  ///< its topic's payload bytes (a node of Store::topic_bytes_)
    Ring<Record> records;  // by commit time; records[i] has sequence head_seq + i
    uint64_t head_seq = 0;
    /// The data-time index: the low 32 bits of each held sample's sequence number, ordered by
    /// (data time, sequence): 4 bytes a sample.
    Ring<uint32_t> by_data;
    ByteChunks bytes;
    /// The search guides of records (by commit time) and of by_data (by data time).
    Spread commit_spread, data_spread;
    uint64_t bytes_held = 0;
    uint64_t samples_total = 0;
    uint64_t first_commit_ever = kNever, min_data_ever = kNever;
    uint64_t last_evicted_commit = 0, max_evicted_data = 0;
    bool any_evicted = false;
    uint64_t cycle_sum = 0, cycle_max = 0;
    /// Where samples were lost: (commit time of the sample after the hole, how many), oldest
    /// first; entries before the oldest held sample are dropped by expire(). Rare: a deque.
    std::deque<std::pair<uint64_t, uint64_t>> gaps;
    uint64_t lost_total = 0;
    /// Samples lost just before the one committed at `commit` (0: none).
    uint64_t lost_before(uint64_t commit) const;
    /// Samples lost before the ones committed in (from, to].
    uint64_t lost_within(uint64_t from, uint64_t to) const;

    /// The newest sample committed with an older data time than the one before it; while it is
    /// held, records are not in data-time order and data-time queries go through by_data.
    uint64_t last_descent_seq = 0;

    /// Holds a sample committed at commit_ns, which is later than every commit before it (the
    /// store makes it so). Its payload is copied.
    void append(uint64_t commit_ns, const Incoming& in)
    {
        const uint64_t seq = head_seq + records.size();
        if (!records.empty() && in.data_ns < records.back().data) last_descent_seq = seq;
        records.push_back({commit_ns, in.data_ns, in.valid_after_ns, in.source_ns, bytes.push(in.data, in.size, seq),
                           static_cast<uint32_t>(in.size)});
        // Mostly in order: append; else after every entry with a data time <= this one's.
        if (by_data.empty() || entry(by_data.back()).data <= in.data_ns) by_data.push_back(uint32_t(seq));
        else by_data.insert(index_after(in.data_ns, true), uint32_t(seq));
        respread();
        bytes_held += in.size;
        ++samples_total;
        if (in.lost_before) {
            gaps.emplace_back(commit_ns, in.lost_before);
            lost_total += in.lost_before;
        }
        first_commit_ever = std::min(first_commit_ever, commit_ns);
        min_data_ever = std::min(min_data_ever, in.data_ns);
    }

    /// The index in records of an index entry (sequence numbers held span far less than 2^32).
    size_t index_of(uint32_t seq32) const { return uint32_t(seq32 - uint32_t(head_seq)); }
    /// The record of an index entry.
    const Record& entry(uint32_t seq32) const { return records[index_of(seq32)]; }
    /// Whether the records held are in data-time order too (the usual case): by_data is then
    /// 0, 1, 2, … and a data-time query reads the records directly, one load a probe, not two.
    bool data_in_commit_order() const { return head_seq >= last_descent_seq; }
    /// The i-th held sample by (data time, sequence).
    const Record& nth_by_data(size_t i) const { return data_in_commit_order() ? records[i] : entry(by_data[i]); }
    /// Index of the first record with commit > t (inclusive) or >= t (!inclusive); size() if none.
    size_t commit_after(uint64_t t, bool inclusive) const
    {
        return search_sorted(records.size(), [this](size_t i) { return records[i].commit; }, t, inclusive,
                             commit_spread.guess(t, records.size()));
    }
    /// Index, in data-time order, of the first sample with data time > t (inclusive) or >= t.
    size_t data_after(uint64_t t, bool inclusive) const
    {
        if (data_in_commit_order()) {
            return search_sorted(records.size(), [this](size_t i) { return records[i].data; }, t, inclusive,
                                 data_spread.guess(t, records.size()));
        }
        return index_after(t, inclusive);
    }
    /// Index in by_data of the first entry with data time > t (inclusive) or >= t.
    size_t index_after(uint64_t t, bool inclusive) const
    {
        // A probe reads by_data[i], then the record it names: mostly records[i] or a neighbour
        // (few samples come late), so that record is fetched along with the first probe's entry.
        const size_t guess = data_spread.guess(t, records.size());
        if (guess < records.size()) __builtin_prefetch(&records[guess]);
        return search_sorted(by_data.size(), [this](size_t i) { return entry(by_data[i]).data; }, t, inclusive, guess);
    }
    /// The sequence number of the held sample a query most likely names, from the search guides
    /// and at most one index entry; records not empty.
    uint64_t likely_seq(Which which, uint64_t t, By by) const
    {
        const size_t last = records.size() - 1;
        if (which == Which::latest) return head_seq + last;
        size_t i = (by == By::commit ? commit_spread : data_spread).guess(t, last);
        if (which == Which::younger) i = std::min(i + 1, last);
        return head_seq + (by == By::commit || data_in_commit_order() ? i : index_of(by_data[i]));
    }
    /// Brings the search guides up to date after samples came or went.
    void respread()
    {
        if (records.empty()) {
            commit_spread = data_spread = {};
            return;
        }
        commit_spread = Spread::of(records.size(), records.front().commit, records.back().commit);
        data_spread = Spread::of(by_data.size(), entry(by_data.front()).data, entry(by_data.back()).data);
    }

    StoredSample copy(const Record& r) const
    {
        const SampleView v = view(r);
        return {v.commit_ns, v.data_ns, v.valid_after_ns, v.source_ns, std::vector<uint8_t>(v.data, v.data + v.size)};
    }

    /// Evicts the oldest sample by commit time; returns its payload size.
    size_t evict_front()
    {
        const Record r = records.front();
        if (by_data.front() == uint32_t(head_seq)) {
            by_data.pop_front();  // data times in order: the usual case
        } else {
            // Among the entries with its data time, it is the first (the oldest sequence).
            by_data.erase(index_after(r.data, false));
        }
        records.pop_front();
        ++head_seq;
        respread();
        bytes.pop();
        bytes_held -= r.size;
        any_evicted = true;
        last_evicted_commit = r.commit;
        max_evicted_data = std::max(max_evicted_data, r.data);
        return r.size;
    }

    /// What an eviction took.
    struct Evicted
    {
        uint64_t samples = 0, bytes = 0;
    };
    /// Evicts the samples that left the retention window before `newest`: those committed more
    /// than window_ns before it (one exactly window_ns old stays).
    Evicted evict_window(uint64_t newest)
    {
        Evicted e;
        while (!records.empty() && records.front().commit + retention.window_ns < newest) {
            e.bytes += evict_front();
            ++e.samples;
        }
        return e;
    }

    /// Why nothing held answers a query for "at or before t" (inclusive) / "before t".
    Status nothing_at_or_before(uint64_t t, By by, bool inclusive) const
    {
        const uint64_t first = by == By::commit ? first_commit_ever : min_data_ever;
        if (first == kNever) return Status::not_found;
        const bool stored_one = inclusive ? first <= t : first < t;
        return stored_one && any_evicted ? Status::evicted : Status::not_found;
    }

    /// The sample a single-sample query names: its status and, when ok, its record.
    Status locate(Which which, uint64_t t, By by, const Record*& rec) const
    {
        switch (which) {
        case Which::latest:
            if (records.empty()) return any_evicted ? Status::evicted : Status::not_found;
            rec = &records.back();
            return Status::ok;
        case Which::at: return before(t, by, true, rec);
        case Which::older: return before(t, by, false, rec);
        case Which::younger: return after(t, by, rec);
        }
        return Status::not_found;
    }
    /// The newest sample at or before t (inclusive) / before t.
    Status before(uint64_t t, By by, bool inclusive, const Record*& rec) const
    {
        const size_t i = by == By::commit ? commit_after(t, inclusive) : data_after(t, inclusive);
        if (i == 0) return nothing_at_or_before(t, by, inclusive);
        rec = by == By::commit ? &records[i - 1] : &nth_by_data(i - 1);
        return Status::ok;
    }
    /// The oldest sample after t.
    Status after(uint64_t t, By by, const Record*& rec) const
    {
        if (records.empty() && !any_evicted) return Status::not_found;
        if (any_evicted && t < (by == By::commit ? last_evicted_commit : max_evicted_data)) return Status::evicted;
        const size_t i = by == By::commit ? commit_after(t, true) : data_after(t, true);
        if (i == records.size()) return Status::not_yet;
        rec = by == By::commit ? &records[i] : &nth_by_data(i);
        return Status::ok;
    }
    Found found(Which which, uint64_t t, By by) const
    {
        if (!records.empty()) bytes.fetch(likely_seq(which, t, by));
        const Record* rec = nullptr;
        const Status st = locate(which, t, by, rec);
        return st == Status::ok ? Found{st, copy(*rec)} : Found{st, {}};
    }
    SampleView view(const Record& r) const
    {
        return {r.commit, r.data, r.valid_after, r.source, r.payload, r.size};
    }
    /// The info block with the counters filled in.
    ObjectInfo described() const;
};

}  // namespace cpm::rtdb::detail
