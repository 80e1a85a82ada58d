#include <cpm/rtdb/Requests.hpp>

#include <regex>
#include <set>
#include <stdexcept>

namespace cpm::rtdb {

namespace {

const std::set<std::string> kKinds{"latest", "at",   "older",  "younger", "range",       "wait_next", "successor",
                                   "snapshot", "info", "search", "list",   "wait_object", "changes"};

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
    w.status(to_string(status));
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
    if (!oid) throw UnknownObject("no object '" + topic + (key.empty() ? "" : "/" + key) + "' (not recorded, or purged after its window)");
    return *oid;
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

void check(const HistoryRequest& rq)
{
    if (!kKinds.count(rq.kind())) {
        std::string known;
        for (const auto& k : kKinds) known += (known.empty() ? "" : ", ") + k;
        throw BadRequest("unknown kind '" + rq.kind() + "' (known: " + known + ")");
    }
    if (!rq.by().empty() && rq.by() != "commit" && rq.by() != "data") {
        throw BadRequest("by is '" + rq.by() + "'; expected commit or data");
    }
    if (rq.kind() == "range" && rq.t1() < rq.t0()) {
        throw BadRequest("range: t1 (" + std::to_string(rq.t1()) + ") is before t0 (" + std::to_string(rq.t0()) + ")");
    }
    if (rq.limit() > kMaxLimit) {
        throw BadRequest("limit " + std::to_string(rq.limit()) + " is above " + std::to_string(kMaxLimit));
    }
    if (rq.timeout_ns() > kMaxTimeoutNs) {
        throw BadRequest("timeout_ns " + std::to_string(rq.timeout_ns()) + " is above 60 s");
    }
    if (rq.kind() == "snapshot" && rq.objects().empty()) throw BadRequest("snapshot: objects is empty");
}

void reply_found(HistoryReply& reply, const Found& f)
{
    reply.status(to_string(f.status));
    if (f.ok()) reply.samples().push_back(to_wire(f.sample, f.status));
}

/// A single-sample query, its payload copied once: from the store straight into the reply.
void reply_viewed(HistoryReply& reply, const Store& store, Oid oid, Which which, uint64_t t, By by)
{
    const Status st = store.view(oid, which, t, by, [&](const SampleView& v) { reply.samples().push_back(to_wire(v, Status::ok)); });
    reply.status(to_string(st));
}

void fill(const Store& store, const HistoryRequest& rq, HistoryReply& reply)
{
    check(rq);
    const By by = rq.by() == "data" ? By::data : By::commit;
    const std::string& kind = rq.kind();
    const auto timeout = std::chrono::nanoseconds(rq.timeout_ns());
    if (kind == "search" || kind == "list") {
        for (const auto& i : store.search(kind == "list" ? Criteria{} : criteria_of(rq))) reply.objects().push_back(to_wire(i));
        reply.status("ok");
        return;
    }
    if (kind == "wait_object") {
        auto found = store.wait_for_object(criteria_of(rq), timeout);
        reply.status(found ? "ok" : "timeout");
        if (found) reply.objects().push_back(to_wire(*found));
        return;
    }
    if (kind == "changes") {
        auto ch = store.changes_since(rq.t0());
        for (const auto& i : ch.created) reply.objects().push_back(to_wire(i));
        for (const auto& i : ch.deleted) reply.objects().push_back(to_wire(i));
        reply.status("ok");
        return;
    }
    if (kind == "snapshot") {
        std::vector<Oid> oids;
        for (const auto& name : rq.objects()) {
            const auto slash = name.find('/');
            oids.push_back(object_named(store, name.substr(0, slash), slash == std::string::npos ? "" : name.substr(slash + 1)));
        }
        auto cut = store.snapshot(rq.t0(), oids, by);
        bool all_ok = true;
        for (size_t i = 0; i < oids.size(); ++i) {
            if (auto info = store.info(oids[i])) reply.objects().push_back(to_wire(*info));
            reply.samples().push_back(to_wire(cut[i].sample, cut[i].status));
            all_ok = all_ok && cut[i].ok();
        }
        reply.status(all_ok ? "ok" : "partial");
        return;
    }
    const Oid oid = object_of(store, rq);
    if (auto info = store.info(oid)) reply.objects().push_back(to_wire(*info));
    if (kind == "info") reply.status("ok");
    else if (kind == "latest") reply_viewed(reply, store, oid, Which::latest, 0, by);
    else if (kind == "at") reply_viewed(reply, store, oid, Which::at, rq.t0(), by);
    else if (kind == "older") reply_viewed(reply, store, oid, Which::older, rq.t0(), by);
    else if (kind == "younger") reply_viewed(reply, store, oid, Which::younger, rq.t0(), by);
    else if (kind == "wait_next") reply_found(reply, store.wait_next(oid, rq.t0(), timeout));
    else if (kind == "successor") reply_found(reply, store.successor(oid, rq.t0(), timeout));
    else if (kind == "range") {
        auto r = store.range(oid, rq.t0(), rq.t1(), by, rq.limit() ? rq.limit() : kDefaultLimit);
        reply.status(to_string(r.status));
        reply.truncated(r.truncated);
        reply.lost(r.lost);
        for (const auto& s : r.samples) reply.samples().push_back(to_wire(s, Status::ok));
    }
}

}  // namespace

bool may_wait(const HistoryRequest& rq)
{
    return rq.timeout_ns() > 0 && (rq.kind() == "wait_next" || rq.kind() == "successor" || rq.kind() == "wait_object");
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
        reply.status("unknown_object");
        reply.error(e.what());
    } catch (const std::exception& e) {
        reply.objects().clear();
        reply.samples().clear();
        reply.status("error");
        reply.error(e.what());
    }
    return reply;
}

}  // namespace cpm::rtdb
