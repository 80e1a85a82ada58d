#include <cpm/rtdb/Store.hpp>

#include <algorithm>
#include <cstring>
#include <limits>
#include <regex>
#include <stdexcept>

namespace cpm::rtdb {

namespace {

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

/// Payload bytes of one object, first in first out, in chunks of 16 KiB (a larger sample gets
/// a chunk of its own). A sample never spans chunks and never moves; a chunk is freed when its
/// last sample is evicted. Unlike one growing buffer, this keeps at most one partly used chunk
/// beyond the payload held.
class ByteChunks
{
public:
    static constexpr size_t kChunk = 16 * 1024;
    /// Stores the bytes of the sample with sequence number seq; returns where they stay until popped.
    const uint8_t* push(const uint8_t* data, size_t size, uint64_t seq)
    {
        if (chunks_.empty() || chunks_.back().capacity - chunks_.back().used < size) {
            // An emptied only chunk too small for this sample goes, so the front always holds the oldest.
            if (!chunks_.empty() && chunks_.back().samples == 0) chunks_.pop_back();
            const size_t cap = std::max(kChunk, size);
            chunks_.push_back({std::unique_ptr<uint8_t[]>(new uint8_t[cap]), cap, 0, 0, 0, 0, 0});
        }
        Chunk& c = chunks_.back();
        if (c.used == 0) {  // a new chunk, or the only one, emptied and begun again
            c.first_seq = seq;
            c.pushed = 0;
            c.stride = size;
        }
        uint8_t* where = c.data.get() + c.used;
        std::memcpy(where, data, size);
        if (size != c.stride) c.stride = 0;
        c.used += size;
        ++c.samples;
        ++c.pushed;
        return where;
    }
    /// Starts fetching the payload of sample seq into the cache, found without its record: while
    /// samples are all of one size, chunks hold equally many and a sample's place follows from
    /// its number (otherwise nothing is fetched). A copying query does this while it still
    /// searches for the record, so that the two cache misses overlap instead of following each
    /// other. It loads the bytes: a prefetch instruction made no difference on this machine
    /// (bench_history_store, side by side), plain loads do.
    void fetch(uint64_t seq) const
    {
        if (chunks_.empty()) return;
        const Chunk& front = chunks_.front();
        if (seq < front.first_seq || front.pushed == 0) return;
        const uint64_t k = (seq - front.first_seq) / front.pushed;
        if (k >= chunks_.size()) return;
        const Chunk& c = chunks_[k];
        if (c.stride == 0 || seq < c.first_seq || seq - c.first_seq >= c.pushed) return;
        const uint8_t* p = c.data.get() + (seq - c.first_seq) * c.stride;
        uint8_t any = 0;
        for (size_t line = 0; line < c.stride; line += 64) any ^= static_cast<const volatile uint8_t*>(p)[line];
        any ^= static_cast<const volatile uint8_t*>(p)[c.stride - 1];
        asm volatile("" : : "r"(any));  // the bytes are wanted in the cache, not their value
    }
    /// The oldest sample is evicted. Samples leave in the order they came, so it lies in the
    /// front chunk.
    void pop()
    {
        Chunk& c = chunks_.front();
        if (--c.samples > 0) return;
        if (chunks_.size() > 1) chunks_.pop_front();
        else c.used = 0;  // the only chunk, empty: start again at its beginning
    }

private:
    struct Chunk
    {
        std::unique_ptr<uint8_t[]> data;
        size_t capacity, used;
        size_t samples;      ///< not yet evicted
        uint64_t first_seq;  ///< of the first sample pushed into it
        size_t pushed;       ///< samples pushed into it
        size_t stride;       ///< their size while all are of one size, else 0
    };
    std::deque<Chunk> chunks_;
};

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

/// A sequence in one circular buffer, oldest first (contiguous, so a lookup by index is an add
/// and a compare, not a deque's block walk). It grows by a quarter at a time: little unused
/// room per element, still amortised O(1) appends at the back and removals at the front.
template <typename T>
class Ring
{
public:
    size_t size() const { return n_; }
    bool empty() const { return n_ == 0; }
    const T& operator[](size_t i) const { return buf_[slot(i)]; }
    T& operator[](size_t i) { return buf_[slot(i)]; }
    const T& front() const { return (*this)[0]; }
    const T& back() const { return (*this)[n_ - 1]; }
    void push_back(const T& x)
    {
        if (n_ == buf_.size()) resize(std::max<size_t>(16, buf_.size() + buf_.size() / 4));
        buf_[slot(n_++)] = x;
    }
    void pop_front()
    {
        if (++head_ == buf_.size()) head_ = 0;
        --n_;
    }
    /// Inserts before index i, moving the elements after it (cheap near the back).
    void insert(size_t i, const T& x)
    {
        push_back(x);
        for (size_t k = n_ - 1; k > i; --k) (*this)[k] = (*this)[k - 1];
        (*this)[i] = x;
    }
    /// Removes index i, moving the elements before it (cheap near the front).
    void erase(size_t i)
    {
        for (size_t k = i; k > 0; --k) (*this)[k] = (*this)[k - 1];
        pop_front();
    }
    /// Gives memory back after a flood has passed.
    void shrink()
    {
        if (buf_.size() > 64 && n_ < buf_.size() / 2) resize(std::max<size_t>(16, n_ + n_ / 4));
    }

private:
    size_t slot(size_t i) const
    {
        size_t k = head_ + i;
        return k >= buf_.size() ? k - buf_.size() : k;
    }
    void resize(size_t capacity)
    {
        std::vector<T> next(capacity);
        for (size_t i = 0; i < n_; ++i) next[i] = (*this)[i];
        buf_.swap(next);
        head_ = 0;
    }
    std::vector<T> buf_;
    size_t head_ = 0, n_ = 0;
};

/// What the store holds of one object; Store::Object adds its lock. A purged object's state is
/// reset to this (its memory given back) and its slot taken by the next new object.
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
    uint64_t lost_before(uint64_t commit) const
    {
        auto it = std::lower_bound(gaps.begin(), gaps.end(), std::make_pair(commit, uint64_t(0)));
        return it != gaps.end() && it->first == commit ? it->second : 0;
    }
    /// Samples lost before the ones committed in (from, to].
    uint64_t lost_within(uint64_t from, uint64_t to) const
    {
        uint64_t n = 0;
        for (const auto& [c, k] : gaps) n += c > from && c <= to ? k : 0;
        return n;
    }

    /// The newest sample committed with an older data time than the one before it; while it is
    /// held, records are not in data-time order and data-time queries go through by_data.
    uint64_t last_descent_seq = 0;

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
    ObjectInfo described() const
    {
        ObjectInfo i = info;
        i.samples_held = records.size();
        i.bytes_held = bytes_held;
        i.samples_total = samples_total;
        i.samples_lost = lost_total;
        i.newest_commit_ns = records.empty() ? 0 : records.back().commit;
        i.oldest_commit_ns = records.empty() ? 0 : records.front().commit;
        i.avg_cycle_s = samples_total > 1 ? double(cycle_sum) * 1e-9 / double(samples_total - 1) : 0;
        i.max_cycle_s = double(cycle_max) * 1e-9;
        return i;
    }
};

}  // namespace

struct Store::Object : ObjectState
{
    mutable std::shared_mutex mutex;
    uint32_t generation = 0;  ///< how often its slot was taken: the oid's high 32 bits
};

Store::Store(StoreOptions options) : options_(options) {}

Store::~Store()
{
    for (Object* o : slots()) delete o;
    for (Object** block : blocks_) delete[] block;
}

Store::Object* Store::slot(Oid oid) const
{
    const uint32_t n = uint32_t(oid);
    if (n == 0 || n >= slots_used_.load(std::memory_order_acquire)) return nullptr;
    return blocks_[n >> kBlockBits][n & kBlockMask];
}

Store::Object* Store::live(Oid oid) const
{
    Object* o = slot(oid);
    return o && o->info.oid == oid ? o : nullptr;
}

std::vector<Store::Object*> Store::slots() const
{
    std::vector<Object*> all;
    const uint32_t n = slots_used_.load(std::memory_order_acquire);
    for (uint32_t i = 1; i < n; ++i) all.push_back(slot(i));
    return all;
}

void Store::set_retention(const std::string& topic, Retention r)
{
    std::unique_lock lock(registry_mutex_);
    retention_[topic] = r;
    for (Object* o : slots()) {
        std::unique_lock ol(o->mutex);
        if (o->info.oid == kNoOid || o->info.topic != topic) continue;
        o->retention = r;
        o->info.history_interval_ns = r.window_ns;
    }
}

Retention Store::retention(const std::string& topic) const
{
    std::shared_lock lock(registry_mutex_);
    auto it = retention_.find(topic);
    return it == retention_.end() ? options_.default_retention : it->second;
}

Oid Store::add_object(ObjectInfo info)
{
    const Retention retention = this->retention(info.topic);
    Oid oid;
    {
        std::unique_lock lock(registry_mutex_);
        Object* o;
        uint32_t n;
        if (!free_slots_.empty()) {
            n = free_slots_.back();
            free_slots_.pop_back();
            o = slot(n);
        } else {
            n = slots_used_.load(std::memory_order_relaxed);
            if ((n >> kBlockBits) >= kBlocks) {
                throw std::length_error("cpm::rtdb::Store: more than " + std::to_string(kBlocks << kBlockBits) + " objects held at once");
            }
            Object**& block = blocks_[n >> kBlockBits];
            if (!block) block = new Object*[size_t(1) << kBlockBits]();
            o = block[n & kBlockMask] = new Object;
        }
        std::unique_lock ol(o->mutex);
        oid = Oid(o->generation) << 32 | n;
        info.oid = oid;
        info.history_interval_ns = retention.window_ns;
        if (info.name.empty()) info.name = info.key.empty() ? info.topic : info.topic + "/" + info.key;
        o->retention = retention;
        o->topic_bytes = &topic_bytes_[info.topic];
        if (info.kind == ObjectKind::instance) by_name_[{info.topic, info.key}] = oid;  // the newest of that name
        o->info = std::move(info);
        if (n == slots_used_.load(std::memory_order_relaxed)) slots_used_.store(n + 1, std::memory_order_release);
    }
    notify();
    return oid;
}

Oid Store::restore_object(ObjectInfo info)
{
    const uint32_t n = uint32_t(info.oid);
    const uint32_t generation = uint32_t(info.oid >> 32);
    const uint64_t interval = info.history_interval_ns, created = info.created_ts;
    {
        std::unique_lock lock(registry_mutex_);
        // Slots up to n are made free ones, so that the object lands in its own.
        while (n != 0 && n >= slots_used_.load(std::memory_order_relaxed) && (n >> kBlockBits) < kBlocks) {
            const uint32_t m = slots_used_.load(std::memory_order_relaxed);
            Object**& block = blocks_[m >> kBlockBits];
            if (!block) block = new Object*[size_t(1) << kBlockBits]();
            block[m & kBlockMask] = new Object;
            free_slots_.push_back(m);
            slots_used_.store(m + 1, std::memory_order_release);
        }
        auto free = std::find(free_slots_.begin(), free_slots_.end(), n);
        if (n != 0 && free != free_slots_.end()) {
            // Taken next by add_object, at the generation the oid names.
            std::iter_swap(free, free_slots_.end() - 1);
            std::unique_lock ol(slot(n)->mutex);
            slot(n)->generation = generation;
        }
    }
    Oid oid = add_object(std::move(info));
    std::unique_lock lock(registry_mutex_);
    Object* o = live(oid);
    std::unique_lock ol(o->mutex);
    o->info.history_interval_ns = interval;
    o->info.created_ts = created;
    return oid;
}

template <typename F>
auto Store::read(Oid oid, F&& f) const
{
    const Object* o = slot(oid);
    if (!o) return f(nullptr);
    std::shared_lock ol(o->mutex);
    return f(o->info.oid == oid ? o : nullptr);
}

void Store::evict_oldest(Object& o)
{
    const size_t n = o.evict_front();
    total_bytes_ -= n;
    *o.topic_bytes -= n;
    ++evicted_;
}

void Store::evict_window(Object& o, uint64_t newest)
{
    while (!o.records.empty() && o.records.front().commit + o.retention.window_ns < newest) evict_oldest(o);
}

void Store::evict_for_budget(Object& obj, uint64_t needed)
{
    uint64_t topic_budget;
    {
        std::shared_lock lock(obj.mutex);
        topic_budget = obj.retention.max_bytes_per_topic;
    }
    auto used = [&](bool whole_store) { return whole_store ? total_bytes_ : *obj.topic_bytes; };
    for (bool whole_store : {false, true}) {
        const uint64_t budget = whole_store ? options_.max_bytes_total : topic_budget;
        if (used(whole_store) + needed <= budget) continue;
        // Evict the oldest samples in scope until 1/16 of the budget is free again, so that a
        // flood pays for the scan once per many samples.
        const uint64_t goal = budget - std::min(budget, needed + budget / 16);
        std::vector<Object*> scope;
        for (Object* o : slots()) {
            if (whole_store || o->topic_bytes == obj.topic_bytes) scope.push_back(o);
        }
        while (used(whole_store) > goal) {
            Object* oldest = nullptr;
            uint64_t oldest_commit = kNever;
            for (auto& o : scope) {
                std::shared_lock ol(o->mutex);
                if (!o->records.empty() && o->records.front().commit < oldest_commit) {
                    oldest_commit = o->records.front().commit;
                    oldest = o;
                }
            }
            if (!oldest) break;
            std::unique_lock ol(oldest->mutex);
            evict_oldest(*oldest);
        }
    }
}

uint64_t Store::commit(Oid oid, const Incoming& in, uint64_t now_ns)
{
    Object* o = live(oid);
    if (!o) return 0;
    evict_for_budget(*o, in.size);
    uint64_t commit_ns;
    {
        std::unique_lock lock(o->mutex);
        const uint64_t last = o->records.empty() ? (o->samples_total ? o->last_evicted_commit : 0) : o->records.back().commit;
        commit_ns = o->samples_total ? std::max(now_ns, last + 1) : now_ns;
        if (o->samples_total) {
            const uint64_t cycle = commit_ns - last;
            o->cycle_sum += cycle;
            o->cycle_max = std::max(o->cycle_max, cycle);
        }
        evict_window(*o, commit_ns);  // the time window, relative to the newest commit
        const uint64_t seq = o->head_seq + o->records.size();
        if (!o->records.empty() && in.data_ns < o->records.back().data) o->last_descent_seq = seq;
        o->records.push_back({commit_ns, in.data_ns, in.valid_after_ns, in.source_ns, o->bytes.push(in.data, in.size, seq),
                              static_cast<uint32_t>(in.size)});
        // Mostly in order: append; else after every entry with a data time <= this one's.
        if (o->by_data.empty() || o->entry(o->by_data.back()).data <= in.data_ns) o->by_data.push_back(uint32_t(seq));
        else o->by_data.insert(o->index_after(in.data_ns, true), uint32_t(seq));
        o->respread();
        o->bytes_held += in.size;
        ++o->samples_total;
        if (in.lost_before) {
            o->gaps.emplace_back(commit_ns, in.lost_before);
            o->lost_total += in.lost_before;
            lost_ += in.lost_before;
        }
        o->first_commit_ever = std::min(o->first_commit_ever, commit_ns);
        o->min_data_ever = std::min(o->min_data_ever, in.data_ns);
    }
    total_bytes_ += in.size;
    *o->topic_bytes += in.size;
    notify();
    return commit_ns;
}

void Store::mark_deleted(Oid oid, uint64_t t_ns)
{
    Object* o = live(oid);
    if (!o) return;
    {
        std::unique_lock lock(o->mutex);
        if (o->info.deleted_ts == 0) o->info.deleted_ts = std::max<uint64_t>(t_ns, 1);
    }
    notify();
}

void Store::expire(uint64_t now_ns)
{
    std::vector<Object*> purge;
    for (Object* o : slots()) {
        std::unique_lock ol(o->mutex);
        if (o->info.oid == kNoOid) continue;
        evict_window(*o, now_ns);
        while (!o->gaps.empty() && (o->records.empty() || o->gaps.front().first < o->records.front().commit)) o->gaps.pop_front();
        o->records.shrink();
        o->by_data.shrink();
        if (o->info.deleted_ts && o->info.deleted_ts + o->retention.window_ns < now_ns) purge.push_back(o);
    }
    if (purge.empty()) return;
    std::unique_lock lock(registry_mutex_);
    for (Object* o : purge) {
        std::unique_lock ol(o->mutex);
        total_bytes_ -= o->bytes_held;
        *o->topic_bytes -= o->bytes_held;
        auto named = by_name_.find({o->info.topic, o->info.key});
        if (named != by_name_.end() && named->second == o->info.oid) by_name_.erase(named);
        free_slots_.push_back(uint32_t(o->info.oid));
        static_cast<ObjectState&>(*o) = ObjectState{};  // oid none; records and payload given back
        ++o->generation;
        ++purged_;
    }
}

void Store::notify()
{
    std::lock_guard lock(wait_mutex_);
    ++version_;
    if (waiters_) wait_cv_.notify_all();
}

Status Store::view_with(Oid oid, Which which, uint64_t t, By by, void (*fn)(void*, const SampleView&), void* ctx) const
{
    return read(oid, [&](const Object* o) {
        if (!o) return Status::unknown_object;
        const Record* rec = nullptr;
        const Status st = o->locate(which, t, by, rec);
        if (st == Status::ok) fn(ctx, o->view(*rec));
        return st;
    });
}

Found Store::copy_of(Oid oid, Which which, uint64_t t, By by) const
{
    return read(oid, [&](const Object* o) { return o ? o->found(which, t, by) : Found{Status::unknown_object, {}}; });
}

Found Store::latest(Oid oid) const { return copy_of(oid, Which::latest, 0, By::commit); }

Found Store::at(Oid oid, uint64_t t, By by) const { return copy_of(oid, Which::at, t, by); }

Found Store::older(Oid oid, uint64_t t, By by) const { return copy_of(oid, Which::older, t, by); }

Found Store::younger(Oid oid, uint64_t t, By by) const { return copy_of(oid, Which::younger, t, by); }

Range Store::range(Oid oid, uint64_t t0, uint64_t t1, By by, size_t limit) const
{
    return read(oid, [&](const Object* o) { return o ? range_of(*o, t0, t1, by, limit) : Range{Status::unknown_object, {}, false}; });
}

Range Store::range_of(const Object& o, uint64_t t0, uint64_t t1, By by, size_t limit)
{
    Range r;
    auto add = [&](const Record& rec) {
        if (r.samples.size() == limit) {
            r.truncated = true;
            return false;
        }
        r.samples.push_back(o.copy(rec));
        return true;
    };
    if (t1 > t0 && by == By::commit) {
        const size_t end = o.commit_after(t1, false);
        for (size_t i = o.commit_after(t0, false); i < end && add(o.records[i]); ++i) {}
    } else if (t1 > t0) {
        const size_t end = o.data_after(t1, false);
        for (size_t i = o.data_after(t0, false); i < end && add(o.nth_by_data(i)); ++i) {}
    }
    if (!r.samples.empty()) {
        uint64_t first = UINT64_MAX, last = 0;
        for (const auto& s : r.samples) {
            first = std::min(first, s.commit_ns);
            last = std::max(last, s.commit_ns);
        }
        r.lost = o.lost_within(first, last);
    }
    // Samples of [t0, t1) were evicted before the first one held: the answer is the part held.
    const bool cut_by_window = o.any_evicted && (by == By::commit ? t0 <= o.last_evicted_commit
                                                                  : t0 <= o.max_evicted_data && o.max_evicted_data < t1);
    if (!r.samples.empty()) r.status = cut_by_window ? Status::partial : Status::ok;
    else if (t1 > t0 && o.nothing_at_or_before(t1, by, false) == Status::evicted &&
             (by == By::commit ? t0 <= o.last_evicted_commit : t0 <= o.max_evicted_data)) r.status = Status::evicted;
    else if (!o.records.empty() && t0 > (by == By::commit ? o.records.back().commit : o.nth_by_data(o.records.size() - 1).data)) r.status = Status::not_yet;
    else r.status = Status::not_found;
    return r;
}

bool Store::retry_on_change(std::chrono::nanoseconds timeout, const std::function<bool()>& attempt) const
{
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    std::unique_lock lock(wait_mutex_);
    ++waiters_;
    struct Leave
    {
        int& n;
        ~Leave() { --n; }
    } leave{waiters_};
    for (;;) {
        const uint64_t seen = version_;
        lock.unlock();
        const bool done = attempt();
        lock.lock();
        if (done) return true;
        if (!wait_cv_.wait_until(lock, deadline, [&] { return version_ != seen; })) return false;
    }
}

Found Store::wait_for(Oid oid, uint64_t after, std::chrono::nanoseconds timeout, bool exact) const
{
    Found f;
    const bool answered = retry_on_change(timeout, [&] {
        f = read(oid, [&](const Object* o) -> Found {
            if (!o) return {Status::unknown_object, {}};
            if (exact) {
                Found next = o->found(Which::younger, after, By::commit);
                if (next.status == Status::evicted) next.status = Status::gap;
                // Samples lost right before the next one: it is not the successor.
                if (next.ok() && o->lost_before(next.sample.commit_ns) > 0) next = {Status::gap, {}};
                if (next.status == Status::not_found) next.status = Status::not_yet;  // nothing stored yet: wait
                return next;
            }
            if (!o->records.empty() && o->records.back().commit > after) return o->found(Which::latest, 0, By::commit);
            return {Status::not_yet, {}};
        });
        return f.status != Status::not_yet;
    });
    return answered ? f : Found{Status::timeout, {}};
}

Found Store::wait_next(Oid oid, uint64_t after, std::chrono::nanoseconds timeout) const { return wait_for(oid, after, timeout, false); }

Found Store::successor(Oid oid, uint64_t after, std::chrono::nanoseconds timeout) const { return wait_for(oid, after, timeout, true); }

std::vector<Found> Store::snapshot(uint64_t t, const std::vector<Oid>& oids, By by) const
{
    // Lock every object (in address order, the same for every reader) before answering any.
    std::vector<const Object*> objs, order;
    for (Oid oid : oids) {
        objs.push_back(slot(oid));
        if (objs.back()) order.push_back(objs.back());
    }
    std::sort(order.begin(), order.end());
    order.erase(std::unique(order.begin(), order.end()), order.end());
    std::vector<std::shared_lock<std::shared_mutex>> locks;
    for (const Object* o : order) locks.emplace_back(o->mutex);
    std::vector<Found> out;
    for (size_t i = 0; i < oids.size(); ++i) {
        const Object* o = objs[i];
        out.push_back(o && o->info.oid == oids[i] ? o->found(Which::at, t, by) : Found{Status::unknown_object, {}});
    }
    return out;
}


std::optional<ObjectInfo> Store::info(Oid oid) const
{
    return read(oid, [](const Object* o) -> std::optional<ObjectInfo> {
        if (!o) return std::nullopt;
        return o->described();
    });
}

std::vector<ObjectInfo> Store::search(const Criteria& c) const
{
    std::optional<std::regex> re;
    if (c.name_regex) re.emplace(*c.name_regex, std::regex::ECMAScript | std::regex::icase);  // throws std::regex_error
    std::vector<ObjectInfo> out;
    for (const Object* o : slots()) {
        std::optional<ObjectInfo> i;
        {
            std::shared_lock ol(o->mutex);
            if (o->info.oid != kNoOid) i = o->described();
        }
        if (!i) continue;
        if (re && !std::regex_search(i->name, *re)) continue;
        if (c.type_name && i->type_name != *c.type_name) continue;
        if (c.parent && i->parent != *c.parent) continue;
        if (c.creator && i->creator != *c.creator && i->creator_guid != *c.creator) continue;
        if (c.kind && i->kind != *c.kind) continue;
        if (c.alive_at && (i->created_ts > *c.alive_at || (i->deleted_ts && i->deleted_ts <= *c.alive_at))) continue;
        out.push_back(std::move(*i));
    }
    return out;
}

std::optional<ObjectInfo> Store::wait_for_object(const Criteria& c, std::chrono::nanoseconds timeout) const
{
    std::vector<ObjectInfo> found;
    if (!retry_on_change(timeout, [&] { return !(found = search(c)).empty(); })) return std::nullopt;
    return found.front();
}

std::optional<Oid> Store::find(const std::string& topic, const std::string& key) const
{
    std::shared_lock lock(registry_mutex_);
    auto it = by_name_.find({topic, key});
    if (it == by_name_.end()) return std::nullopt;
    return it->second;
}

Changes Store::changes_since(uint64_t t_ns) const
{
    Changes ch;
    for (auto& i : search({})) {
        if (i.created_ts > t_ns) ch.created.push_back(i);
        if (i.deleted_ts > t_ns) ch.deleted.push_back(i);
    }
    return ch;
}

StoreStats Store::stats() const
{
    StoreStats s;
    for (const Object* o : slots()) {
        std::shared_lock ol(o->mutex);
        if (o->info.oid == kNoOid) continue;
        ++s.objects;
        if (!o->info.deleted_ts) ++s.alive;
        s.samples += o->records.size();
        s.bytes += o->bytes_held;
    }
    s.evicted = evicted_;
    s.purged_objects = purged_;
    s.lost = lost_;
    return s;
}

}  // namespace cpm::rtdb
