#include "Registry.hpp"

#include <cpm/Error.hpp>

namespace cpm::rtdb {

void Registry::process_found(const rtps::GuidPrefix_t& prefix, const std::string& name, uint64_t now)
{
    if (auto known = processes_.find(prefix); known != processes_.end() && !known->second.gone) return;
    processes_[prefix] = {out_.add({.kind = ObjectKind::process, .name = name, .type_name = "participant", .creator = name,
                                    .creator_guid = guid_prefix_text(prefix), .created_ts = now}),
                          name};
}

void Registry::process_gone(const rtps::GuidPrefix_t& prefix, uint64_t now)
{
    if (auto it = processes_.find(prefix); it != processes_.end() && !it->second.gone) {
        it->second.gone = true;
        out_.deleted(it->second.oid, now);
    }
    for (auto& [topic, instances] : instances_) {
        for (auto& [handle, inst] : instances) {
            std::erase_if(inst.writers, [&](const rtps::GUID_t& w) { return w.guidPrefix == prefix; });
            if (inst.writers.empty()) end(inst, now);
        }
    }
}

void Registry::writer_gone(const std::string& topic, const rtps::GUID_t& writer, uint64_t now)
{
    auto t = instances_.find(topic);
    if (t == instances_.end()) return;
    for (auto& [handle, inst] : t->second) {
        if (inst.writers.erase(writer) && inst.writers.empty()) end(inst, now);
    }
}

Oid Registry::instance(const std::string& topic, const rtps::InstanceHandle_t& handle, const rtps::GUID_t& writer,
                       const std::function<Naming()>& naming, uint64_t now)
{
    auto& inst = instances_[topic][handle];
    if (inst.oid == kNoOid || inst.deleted) {
        auto proc = processes_.find(writer.guidPrefix);
        const ProcessRec creator = proc == processes_.end() ? ProcessRec{} : proc->second;
        inst = InstanceRec{};
        const Naming n = naming();
        try {
            inst.oid = out_.add({.topic = topic, .key = n.key, .type_name = n.type_name, .parent = creator.oid,
                                 .creator = creator.name, .creator_guid = guid_prefix_text(writer.guidPrefix), .created_ts = now,
                                 .data_time = n.data_time});
        } catch (const Error&) {  // millions of instances held at once (Store::add_object)
            instances_[topic].erase(handle);
            return kNoOid;
        }
    }
    inst.writers.insert(writer);
    return inst.oid;
}

void Registry::instance_ended(const std::string& topic, const rtps::InstanceHandle_t& handle, uint64_t now)
{
    auto t = instances_.find(topic);
    if (t == instances_.end()) return;
    if (auto it = t->second.find(handle); it != t->second.end()) end(it->second, now);
}

void Registry::end(InstanceRec& inst, uint64_t now)
{
    if (inst.deleted) return;
    inst.deleted = true;
    out_.deleted(inst.oid, now);
}

}  // namespace cpm::rtdb
