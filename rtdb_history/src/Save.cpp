#include "Save.hpp"

#include <cpm/rtdb/IdlDecoder.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <limits>
#include <optional>
#include <sstream>
#include <tuple>
#include <vector>

namespace cpm::rtdb {

Save::Save(SaveSpan span) : span_(std::move(span))
{
    writer_ = std::make_unique<RecordingWriter>(span_.path, RecordingOptions{.name = span_.name,
                                                                             // a save copies the held span at once
                                                                             .max_queued_bytes = std::numeric_limits<uint64_t>::max() / 4});
}

void Save::start(const Store& store)
{
    struct Held
    {
        Oid oid;
        StoredSample sample;
    };
    std::vector<Held> held;
    std::vector<ObjectInfo> objects = store.search({});
    std::sort(objects.begin(), objects.end(), [](const ObjectInfo& a, const ObjectInfo& b) { return std::tie(a.created_ts, a.oid) < std::tie(b.created_ts, b.oid); });
    for (const auto& o : objects) {
        if (o.kind == ObjectKind::instance && !wanted(o.topic)) continue;
        oids_.insert(o.oid);
        writer_->object_added(o);
        if (o.kind != ObjectKind::instance) continue;
        auto r = store.range(o.oid, span_.from_ns, span_.to_ns, By::data, std::numeric_limits<size_t>::max());
        for (auto& s : r.samples) held.push_back({o.oid, std::move(s)});
    }
    std::stable_sort(held.begin(), held.end(), [](const Held& a, const Held& b) { return a.sample.commit_ns < b.sample.commit_ns; });
    for (const auto& h : held) {
        const Incoming in{h.sample.data_ns, h.sample.valid_after_ns, h.sample.source_ns, h.sample.payload.data(), h.sample.payload.size(), 0};
        writer_->sample_committed(h.oid, in, h.sample.commit_ns);
    }
    for (const auto& o : objects) {
        if (o.deleted_ts && oids_.count(o.oid)) writer_->object_deleted(o.oid, o.deleted_ts);
    }
}

void Save::object_added(const ObjectInfo& info)
{
    if (info.kind == ObjectKind::instance && !wanted(info.topic)) return;
    oids_.insert(info.oid);
    writer_->object_added(info);
}

void Save::sample_committed(Oid oid, const Incoming& sample, uint64_t commit_ns)
{
    if (!oids_.count(oid) || sample.data_ns < span_.from_ns || sample.data_ns >= span_.to_ns) return;
    writer_->sample_committed(oid, sample, commit_ns);
}

void Save::object_deleted(Oid oid, uint64_t deleted_ns)
{
    if (oids_.count(oid)) writer_->object_deleted(oid, deleted_ns);
}

SaveResult Save::finish()
{
    writer_->close();
    const auto c = writer_->counters();
    return {span_.path, c.written, oids_.size(), c.error.empty() && c.dropped > 0 ? std::to_string(c.dropped) + " samples dropped" : c.error};
}

TriggerSink::TriggerSink(std::vector<SaveTrigger> triggers, std::function<void(const Fired&)> fire)
    : triggers_(std::move(triggers)), fire_(std::move(fire))
{
}

void TriggerSink::object_added(const ObjectInfo& info)
{
    for (const auto& t : triggers_) {
        if (t.topic == info.topic) objects_[info.oid] = {info.type_name, info.key};
    }
}

void TriggerSink::sample_committed(Oid oid, const Incoming& sample, uint64_t commit_ns)
{
    const auto o = objects_.find(oid);
    if (o == objects_.end()) return;
    std::optional<nlohmann::json> decoded;  // once, for the triggers with a field
    for (size_t i = 0; i < triggers_.size(); ++i) {
        const SaveTrigger& t = triggers_[i];
        if (!t.field.empty()) {
            if (!decoded) {
                const IdlDecoder* types = IdlDecoder::lab_types();
                decoded = types ? types->decode(o->second.first, sample.data, sample.size) : std::nullopt;
                if (!decoded) decoded = nlohmann::json();
            }
            const nlohmann::json* v = &*decoded;
            std::stringstream path(t.field);
            for (std::string part; v && std::getline(path, part, '.');) v = v->is_object() && v->contains(part) ? &(*v)[part] : nullptr;
            if (!v) continue;
            const std::string text = v->is_string() ? v->get<std::string>() : v->dump();
            // On the edge: when the object's samples begin to match (a state entered), not on
            // every sample of it.
            bool& was = matching_[{i, oid}];
            const bool now = (text == t.value) == t.equal;
            const bool entered = now && !was;
            was = now;
            if (!entered) continue;
        }
        fire_({i, o->second.second, commit_ns, sample.data_ns});
    }
}

}  // namespace cpm::rtdb
