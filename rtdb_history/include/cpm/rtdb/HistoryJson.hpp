#pragma once
// The history's answers as JSON, the one form `cpm history --json`, `cpm dump --json` and every
// later reader of the history (a recording, the monitor) print (DESIGN §6):
//   an object  {"oid", "name", "kind", "topic", "key", "type", "parent", "creator", "creator_guid",
//               "created_ns", "deleted_ns", "data_time", "history_interval_ns", "samples_held",
//               "bytes_held", "samples_total", "samples_lost", "rate_hz", "avg_cycle_s",
//               "max_cycle_s", "newest_age_s"}
//   a sample   {"status", "topic", "key", "type", "commit_ns", "data_ns", "valid_after_ns",
//               "source_ns", "data": {…IDL fields…}}  ("payload_base64" for a type not in the IDL)
#include <cpm/rtdb/IdlDecoder.hpp>

#include <HistoryReply.h>

#include <nlohmann/json.hpp>

#include <cstdint>
#include <optional>
#include <string>

namespace cpm::rtdb {

/// An object's info block; rate and age of its newest sample as of now_ns.
nlohmann::json object_json(const HistoryObject& o, uint64_t now_ns);
/// A sample, its fields decoded by `types` when they describe the object's type. Without the
/// object (or the type) the payload is given as base64.
nlohmann::json sample_json(const HistorySample& s, const HistoryObject* o, const IdlDecoder* types);

/// An oid for people: its slot, and ".generation" once the slot was used before ("7", "7.2").
std::string oid_text(uint64_t oid);
/// An oid as oid_text prints it, or as a plain number; nullopt when it is neither.
std::optional<uint64_t> oid_from_text(const std::string& text);

}  // namespace cpm::rtdb
