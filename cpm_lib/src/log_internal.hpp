#pragma once
#include <mutex>
#include <set>
#include <string>

namespace cpm::detail {

/// Reports a problem that cannot be thrown (in a worker or DDS thread) on stderr, stamped
/// with the time and the node id.
void log_error(const std::string& message);

/// Logs a warning through cpm::Logging from a thread of its own (started on first use), for
/// DDS callbacks: writing the log topic from inside one may create a DataWriter or deliver to a
/// reader of this process while Fast DDS holds its locks. Never blocks.
void log_warning_later(std::string message);

/// One reader's or writer's incompatible-QoS matches, each policy logged once (later), naming
/// the topic, the policy and both sides' values where they follow from ours (reliability,
/// durability).
class IncompatibleQos
{
public:
    IncompatibleQos(bool reader, std::string topic, bool reliable, bool transient_local)
        : reader_(reader), topic_(std::move(topic)), reliable_(reliable), transient_local_(transient_local)
    {
    }
    /// From the DDS listener: logs the policy's first mismatch through log_warning_later.
    void report(int policy_id);

private:
    bool reader_;
    std::string topic_;
    bool reliable_, transient_local_;
    std::mutex mutex_;
    std::set<int> reported_;
};

}  // namespace cpm::detail
