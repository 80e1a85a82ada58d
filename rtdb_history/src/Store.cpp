#include <cpm/rtdb/Store.hpp>

#include <cpm/Error.hpp>

#include "ObjectState.hpp"

#include <algorithm>
#include <regex>

namespace cpm::rtdb {

using detail::kNever;
using detail::ObjectState;
using detail::Record;

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
                throw Error("cpm::rtdb::Store: more than " + std::to_string(kBlocks << kBlockBits) + " objects held at once");
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
        if (info.kind == ObjectKind::instance) by_name_[{info.topic, info.key}].push_back(oid);  // the newest of that name last
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
    const ObjectState::Evicted e = o.evict_window(newest);
    if (e.samples == 0) return;
    total_bytes_ -= e.bytes;
    *o.topic_bytes -= e.bytes;
    evicted_ += e.samples;
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
        o->append(commit_ns, in);
        if (in.lost_before) lost_ += in.lost_before;
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
        if (auto named = by_name_.find({o->info.topic, o->info.key}); named != by_name_.end()) {
            std::erase(named->second, o->info.oid);
            if (named->second.empty()) by_name_.erase(named);
        }
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
    if (c.name_regex) {
        try {
            re.emplace(*c.name_regex, std::regex::ECMAScript | std::regex::icase);
        } catch (const std::regex_error& e) {
            throw Error("name_regex '" + *c.name_regex + "' is not a regular expression: " + e.what());
        }
    }
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
    return it->second.back();
}

std::vector<Oid> Store::named(const std::string& topic, const std::string& key) const
{
    std::shared_lock lock(registry_mutex_);
    auto it = by_name_.find({topic, key});
    return it == by_name_.end() ? std::vector<Oid>{} : it->second;
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
