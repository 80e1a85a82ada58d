#pragma once
// An independent referee for every MCAP file the tests write: the format's reference reader
// (@mcap/core, in Node) opens it indexed and streamed, checks every CRC, reads each message in
// log time order and decodes it with the IDL the file embeds (Foxglove's omgidl parser and CDR
// reader), and each message is compared, field by field, with what `cpm history --file FILE
// --json` answers for it.
#include <nlohmann/json.hpp>

#include <string>
#include <vector>

namespace cpm_test {

/// "" when the reference reader reads `file` whole and every message equals cpm's answer (and
/// cpm answers no sample the reader did not read); else what differs, naming the topic, key,
/// commit time and field. `expected_messages` (when not negative) is the count both must read.
/// Channels cpm derives for viewers (metadata cpm.derived: Foxglove's /tf) must decode and are
/// not compared.
std::string mcap_differences(const std::string& file, long expected_messages = -1);

/// The reference reader's lines for `file`: one per message in log time order ({topic, log_time,
/// publish_time, sequence, derived, data}, 64-bit integers as text), then the totals; none, and
/// `error` set, when it refuses the file.
std::vector<nlohmann::json> mcap_reference_read(const std::string& file, std::string& error);

}  // namespace cpm_test
