#include <cpm/rtdb/Requests.hpp>

#include <regex>
#include <set>
#include <stdexcept>

namespace cpm::rtdb {

namespace {

using history::Kind;

/// A malformed request: the reply's status is "error" and this is its message.
struct BadRequest : std::runtime_error
{
    using std::runtime_error::runtime_error;
};

struct UnknownObject : std::runtime_error
{
    using std::runtime_error::runtime_error;
};

HistorySample to_wire(const SampleView& s, Status status)
{
    HistorySample w;
    w.commit_ns(s.commit_ns);
    w.data_ns(s.data_ns);
    w.valid_after_ns(s.valid_after_ns);
    w.source_ns(s.source_ns);
    w.status(std::string(to_string(status)));
    w.payload().assign(s.data, s.data + s.size);
    return w;
}

HistorySample to_wire(const StoredSample& s, Status status)
{
    return to_wire(SampleView{s.commit_ns, s.data_ns, s.valid_after_ns, s.source_ns, s.payload.data(), s.payload.size()}, status);
}

/// The object named by topic and key.
Oid object_named(const Store& store, const std::string& topic, const std::string& key)
{
    auto oid = store.find(topic, key);
    if (oid) return *oid;
    if (key.empty()) {
        // A keyed topic asked without its key: say so, with the keys it has.
        std::set<std::string> keys;
        for (const auto& o : store.search({.kind = ObjectKind::instance})) {
            if (o.topic == topic && !o.key.empty()) keys.insert(o.key);
        }
        if (!keys.empty()) {
            std::string list;
            for (const auto& k : keys) list += (list.empty() ? "" : ", ") + k;
            throw UnknownObject("topic '" + topic + "' is keyed: ask for one key (--key K), one of " + list);
        }
    }
    throw UnknownObject("no object '" + topic + (key.empty() ? "" : "/" + key) + "' (not recorded, or purged after its window)");
}

/// The request's object: its oid, else its topic and key.
Oid object_of(const Store& store, const HistoryRequest& rq)
{
    if (rq.oid() != 0) {
        if (!store.info(rq.oid())) throw UnknownObject("no object with oid " + std::to_string(rq.oid()) + " (purged or never seen)");
        return rq.oid();
    }
    if (rq.topic().empty()) throw BadRequest("kind '" + rq.kind() + "' needs an object: topic (and key) or oid");
    return object_named(store, rq.topic(), rq.key());
}

Kind kind_of(const HistoryRequest& rq)
{
    const auto kind = history::kind_from(rq.kind());
    if (!kind) throw BadRequest("unknown kind '" + rq.kind() + "' (known: " + history::known_kinds() + ")");
    return *kind;
}

Criteria criteria_of(const HistoryRequest& rq)
{
    Criteria c;
    if (!rq.name_regex().empty()) c.name_regex = rq.name_regex();
    if (!rq.type_name().empty()) c.type_name = rq.type_name();
    if (rq.parent()) c.parent = rq.parent();
    if (!rq.creator().empty()) c.creator = rq.creator();
    if (rq.alive_at()) c.alive_at = rq.alive_at();
    if (c.name_regex) {
        try {
            std::regex check(*c.name_regex, std::regex::ECMAScript | std::regex::icase);
        } catch (const std::regex_error& e) {
            throw BadRequest("name_regex '" + *c.name_regex + "' is not a regular expression: " + e.what());
        }
    }
    return c;
}

/// The request's kind and time, or BadRequest naming what is wrong.
std::pair<Kind, By> check(const HistoryRequest& rq)
{
    const auto kind = kind_of(rq);
    const auto by = history::by_from(rq.by());
    if (!by) throw BadRequest("by is '" + rq.by() + "'; expected commit or data");
    if (kind == Kind::range && rq.t1() < rq.t0()) {
        throw BadRequest("range: t1 (" + std::to_string(rq.t1()) + ") is before t0 (" + std::to_string(rq.t0()) + ")");
    }
    if (rq.limit() > kMaxLimit) {
        throw BadRequest("limit " + std::to_string(rq.limit()) + " is above " + std::to_string(kMaxLimit));
    }
    if (rq.timeout_ns() > kMaxTimeoutNs) {
        throw BadRequest("timeout_ns " + std::to_string(rq.timeout_ns()) + " is above 60 s");
    }
    if (kind == Kind::snapshot && rq.objects().empty()) throw BadRequest("snapshot: objects is empty");
    return {kind, *by};
}

void set_status(HistoryReply& reply, Status s) { reply.status(std::string(to_string(s))); }

void reply_found(HistoryReply& reply, const Found& f)
{
    set_status(reply, f.status);
    if (f.ok()) reply.samples().push_back(to_wire(f.sample, f.status));
}

/// A single-sample query, its payload copied once: from the store straight into the reply.
void reply_viewed(HistoryReply& reply, const Store& store, Oid oid, Which which, uint64_t t, By by)
{
    const Status st = store.view(oid, which, t, by, [&](const SampleView& v) { reply.samples().push_back(to_wire(v, Status::ok)); });
    set_status(reply, st);
}

/// Every object of topic and key, oldest first (a writer restarted after it was marked dead
/// leaves two); throws naming what is wrong when there is none.
std::vector<Oid> objects_named(const Store& store, const std::string& topic, const std::string& key)
{
    std::vector<Oid> all = store.named(topic, key);
    if (all.empty()) all.push_back(object_named(store, topic, key));  // throws
    return all;
}

/// The objects a question about a time may be answered from, oldest first: those of its topic
/// and key, or the one it names by oid.
std::vector<Oid> candidates(const Store& store, const HistoryRequest& rq)
{
    if (rq.oid() != 0 || rq.topic().empty()) return {object_of(store, rq)};  // by oid, or the error naming what is missing
    return objects_named(store, rq.topic(), rq.key());
}

/// The object of `oids` (oldest first) that answers `which` at t: the newest with a sample at or
/// before t, the oldest with one after it; the newest object when none has one.
Oid object_of_time(const Store& store, const std::vector<Oid>& oids, Which which, uint64_t t, By by)
{
    auto has_answer = [&](Oid oid) { return store.view(oid, which, t, by, [](const SampleView&) {}) == Status::ok; };
    if (oids.size() > 1 && which == Which::younger) {
        for (Oid oid : oids)
            if (has_answer(oid)) return oid;
    } else if (oids.size() > 1) {
        for (auto it = oids.rbegin(); it != oids.rend(); ++it)
            if (has_answer(*it)) return *it;
    }
    return oids.back();
}

/// A question about a time: answered from the object of that time.
void reply_at_time(HistoryReply& reply, const Store& store, const std::vector<Oid>& oids, Which which, uint64_t t, By by)
{
    const Oid chosen = object_of_time(store, oids, which, t, by);
    if (auto info = store.info(chosen)) reply.objects().push_back(to_wire(*info));
    reply_viewed(reply, store, chosen, which, t, by);
}

/// A range asked by name: the samples of every object of that name within it, oldest object first.
void reply_range(HistoryReply& reply, const Store& store, const std::vector<Oid>& oids, const HistoryRequest& rq, By by)
{
    size_t limit = rq.limit() ? rq.limit() : kDefaultLimit;
    Status status = Status::not_found;
    uint64_t lost = 0;
    bool truncated = false;
    for (Oid oid : oids) {
        auto r = store.range(oid, rq.t0(), rq.t1(), by, limit);  // limit 0: truncated if it holds any there
        if (!r.samples.empty() || (oid == oids.back() && reply.objects().empty())) {
            if (auto info = store.info(oid)) reply.objects().push_back(to_wire(*info));
        }
        for (const auto& sample : r.samples) reply.samples().push_back(to_wire(sample, Status::ok));
        limit -= r.samples.size();
        lost += r.lost;
        truncated = truncated || r.truncated;
        // ok once any object held samples there, partial if one's window cut them; else what
        // the newest says.
        if (!r.samples.empty() && (status == Status::not_found || r.status == Status::partial)) status = r.status;
        else if (reply.samples().empty() && oid == oids.back()) status = r.status;
    }
    reply.truncated(truncated);
    reply.lost(lost);
    set_status(reply, status);
}

void fill(const Store& store, const HistoryRequest& rq, HistoryReply& reply)
{
    const auto [kind, by] = check(rq);
    const auto timeout = std::chrono::nanoseconds(rq.timeout_ns());
    switch (kind) {
    case Kind::search:
    case Kind::list:
        for (const auto& i : store.search(kind == Kind::list ? Criteria{} : criteria_of(rq))) reply.objects().push_back(to_wire(i));
        return set_status(reply, Status::ok);
    case Kind::wait_object: {
        auto found = store.wait_for_object(criteria_of(rq), timeout);
        if (found) reply.objects().push_back(to_wire(*found));
        return set_status(reply, found ? Status::ok : Status::timeout);
    }
    case Kind::changes: {
        auto ch = store.changes_since(rq.t0());
        for (const auto& i : ch.created) reply.objects().push_back(to_wire(i));
        for (const auto& i : ch.deleted) reply.objects().push_back(to_wire(i));
        return set_status(reply, Status::ok);
    }
    case Kind::save: throw BadRequest("save: only the live history service saves (cpm history save, without --file)");
    case Kind::snapshot: {
        std::vector<Oid> oids;
        for (const auto& name : rq.objects()) {
            const auto slash = name.find('/');
            const std::string topic = name.substr(0, slash), key = slash == std::string::npos ? "" : name.substr(slash + 1);
            oids.push_back(object_of_time(store, objects_named(store, topic, key), Which::at, rq.t0(), by));
        }
        auto cut = store.snapshot(rq.t0(), oids, by);
        bool all_ok = true;
        for (size_t i = 0; i < oids.size(); ++i) {
            if (auto info = store.info(oids[i])) reply.objects().push_back(to_wire(*info));
            reply.samples().push_back(to_wire(cut[i].sample, cut[i].status));
            all_ok = all_ok && cut[i].ok();
        }
        return set_status(reply, all_ok ? Status::ok : Status::partial);
    }
    default: break;
    }
    // The kinds about a time: the object of that time among those of the name.
    switch (kind) {
    case Kind::at: return reply_at_time(reply, store, candidates(store, rq), Which::at, rq.t0(), by);
    case Kind::older: return reply_at_time(reply, store, candidates(store, rq), Which::older, rq.t0(), by);
    case Kind::younger: return reply_at_time(reply, store, candidates(store, rq), Which::younger, rq.t0(), by);
    case Kind::range: return reply_range(reply, store, candidates(store, rq), rq, by);
    default: break;
    }
    // The kinds about one object, the newest of its name.
    const Oid oid = object_of(store, rq);
    if (auto info = store.info(oid)) reply.objects().push_back(to_wire(*info));
    switch (kind) {
    case Kind::info: return set_status(reply, Status::ok);
    case Kind::latest: return reply_viewed(reply, store, oid, Which::latest, 0, by);
    case Kind::wait_next: return reply_found(reply, store.wait_next(oid, rq.t0(), timeout));
    case Kind::successor: return reply_found(reply, store.successor(oid, rq.t0(), timeout));
    default: return;  // answered above
    }
}

}  // namespace

bool may_wait(const HistoryRequest& rq)
{
    const auto kind = history::kind_from(rq.kind());
    return rq.timeout_ns() > 0 && kind && history::may_wait(*kind);
}

HistoryObject to_wire(const ObjectInfo& i)
{
    HistoryObject w;
    w.oid(i.oid);
    w.is_process(i.kind == ObjectKind::process);
    w.name(i.name);
    w.topic(i.topic);
    w.key(i.key);
    w.type_name(i.type_name);
    w.parent(i.parent);
    w.creator(i.creator);
    w.creator_guid(i.creator_guid);
    w.created_ts(i.created_ts);
    w.deleted_ts(i.deleted_ts);
    w.history_interval_ns(i.history_interval_ns);
    w.samples_held(i.samples_held);
    w.bytes_held(i.bytes_held);
    w.samples_total(i.samples_total);
    w.samples_lost(i.samples_lost);
    w.newest_commit_ns(i.newest_commit_ns);
    w.oldest_commit_ns(i.oldest_commit_ns);
    w.avg_cycle_s(i.avg_cycle_s);
    w.max_cycle_s(i.max_cycle_s);
    w.data_time(i.data_time);
    return w;
}

HistoryReply answer(const Store& store, const HistoryRequest& rq)
{
    HistoryReply reply;
    reply.client_id(rq.client_id());
    reply.request_id(rq.request_id());
    try {
        fill(store, rq, reply);
    } catch (const UnknownObject& e) {
        set_status(reply, Status::unknown_object);
        reply.error(e.what());
    } catch (const std::exception& e) {
        reply.objects().clear();
        reply.samples().clear();
        set_status(reply, Status::error);
        reply.error(e.what());
    }
    return reply;
}

}  // namespace cpm::rtdb
