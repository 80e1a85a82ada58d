#pragma once
// Per-topic QoS a whole lab runs with, set from outside the programs: `cpm lab run` puts a
// scenario's `qos:` into CPM_QOS_OVERRIDES for every process it starts, and every Reader and
// Writer made through cpm_lib then uses it for that topic, so both sides of a topic change
// together and still match.
//
//   CPM_QOS_OVERRIDES='{"vehicleState": {"reliable": true, "history_depth": 5}}'
#include <cpm/ReaderOptions.hpp>
#include <cpm/WriterOptions.hpp>

#include <map>
#include <optional>
#include <string>

namespace cpm {

struct QosOverride
{
    std::optional<bool> reliable;
    std::optional<bool> transient_local;
    std::optional<int> history_depth;  ///< keep the last N per instance (also ends keep_all)
};

using QosOverrides = std::map<std::string, QosOverride>;  ///< by topic name

inline constexpr const char* kQosOverridesVariable = "CPM_QOS_OVERRIDES";

/// Reads the JSON form (an object of topic: {reliable, transient_local, history_depth}).
/// Throws cpm::Error naming `source`, the JSON path and the value that is wrong.
QosOverrides parse_qos_overrides(const std::string& json, const std::string& source);
/// The JSON form parse_qos_overrides reads.
std::string to_json(const QosOverrides& overrides);

/// The overrides of this process: CPM_QOS_OVERRIDES (read again when it changes). Throws
/// cpm::Error when it is malformed, so a Reader or Writer is never made with a silently
/// ignored override.
QosOverrides qos_overrides();

/// `options` with the overrides for `topic` applied.
WriterOptions overridden(WriterOptions options, const std::string& topic, const QosOverrides& overrides);
ReaderOptions overridden(ReaderOptions options, const std::string& topic, const QosOverrides& overrides);

}  // namespace cpm
