#include <cpm/rtdb/HistoryJson.hpp>

#include <cpm/HistoryClient.hpp>

#include <algorithm>
#include <charconv>

namespace cpm::rtdb {

nlohmann::json object_json(const HistoryObject& o, uint64_t now)
{
    return {{"oid", o.oid()},
            {"name", o.name()},
            {"kind", o.is_process() ? "process" : "instance"},
            {"topic", o.topic()},
            {"key", o.key()},
            {"type", o.type_name()},
            {"parent", o.parent()},
            {"creator", o.creator()},
            {"creator_guid", o.creator_guid()},
            {"created_ns", o.created_ts()},
            {"deleted_ns", o.deleted_ts()},
            {"data_time", o.data_time()},
            {"history_interval_ns", o.history_interval_ns()},
            {"samples_held", o.samples_held()},
            {"bytes_held", o.bytes_held()},
            {"samples_total", o.samples_total()},
            {"samples_lost", o.samples_lost()},
            {"rate_hz", cpm::update_rate_hz(o, now)},
            {"avg_cycle_s", o.avg_cycle_s()},
            {"max_cycle_s", o.max_cycle_s()},
            {"newest_age_s", o.newest_commit_ns() ? double(now - std::min(now, o.newest_commit_ns())) * 1e-9 : -1.0}};
}

nlohmann::json sample_json(const HistorySample& s, const HistoryObject* o, const IdlDecoder* types)
{
    nlohmann::json j{{"status", s.status()},         {"commit_ns", s.commit_ns()}, {"data_ns", s.data_ns()},
                     {"valid_after_ns", s.valid_after_ns()}, {"source_ns", s.source_ns()}};
    if (o) {
        j["topic"] = o->topic();
        j["key"] = o->key();
        j["type"] = o->type_name();
        // A type without a Header has no create_stamp: data_ns is the writer's source timestamp.
        if (o->data_time() == "source_timestamp") j["data_time"] = "source_timestamp";
        j.update(describe(types, o->type_name(), s.payload()));
        return j;
    }
    j["payload_base64"] = base64(s.payload());
    return j;
}

std::string oid_text(uint64_t oid)
{
    const uint64_t slot = oid & 0xffffffffull, generation = oid >> 32;
    return generation ? std::to_string(slot) + "." + std::to_string(generation) : std::to_string(slot);
}

std::optional<uint64_t> oid_from_text(const std::string& text)
{
    auto number = [](std::string_view t, uint64_t max) -> std::optional<uint64_t> {
        uint64_t v = 0;
        const auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
        if (t.empty() || ec != std::errc() || end != t.data() + t.size() || v > max) return std::nullopt;
        return v;
    };
    const auto dot = text.find('.');
    if (dot == std::string::npos) {
        auto v = number(text, INT64_MAX);
        return v && *v > 0 ? v : std::nullopt;
    }
    const auto slot = number(std::string_view(text).substr(0, dot), UINT32_MAX);
    const auto generation = number(std::string_view(text).substr(dot + 1), UINT32_MAX);
    if (!slot || !generation || *slot == 0) return std::nullopt;
    return *generation << 32 | *slot;
}

}  // namespace cpm::rtdb
