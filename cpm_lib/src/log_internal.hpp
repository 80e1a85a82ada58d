#pragma once
#include <string>

namespace cpm::detail {

/// Reports a problem that cannot be thrown (in a worker or DDS thread) on stderr, stamped
/// with the time and the node id.
void log_error(const std::string& message);

/// Logs a warning through cpm::Logging from a thread of its own (started on first use), for
/// DDS callbacks: writing the log topic from inside one may create a DataWriter or deliver to a
/// reader of this process while Fast DDS holds its locks. Never blocks.
void log_warning_later(std::string message);

/// The message for an incompatible-QoS match: names the topic, the policy and both sides'
/// values where they follow from ours (reliability, durability). `reader`: this side reads.
std::string incompatible_qos_message(bool reader, const std::string& topic, int policy_id, bool our_reliable,
                                     bool our_transient_local);

}  // namespace cpm::detail
