#pragma once
// cpm::rtdb::TopicProbe — what is on the lab's topics, from DDS discovery alone (no history
// service needed), as `ros2 topic list|info|echo|hz` shows it: every topic with its type, its
// writers and readers, and the samples of any topic as they come off the wire, for types cpm
// was never compiled with too.
#include <cpm/Participant.hpp>

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace cpm::rtdb {

/// One writer or reader of a topic, as discovery announced it.
struct Endpoint
{
    std::string participant;  ///< the participant's name (a node id), or its GUID prefix if not yet known
    bool reliable = false;
    bool transient_local = false;
};

struct TopicInfo
{
    std::string name, type_name;
    bool keyed = false;
    std::vector<Endpoint> writers, readers;
};

/// Another participant on the domain, as discovery announced it.
struct ParticipantSeen
{
    std::string name;                    ///< "(unnamed)" when it gave none
    std::vector<std::string> addresses;  ///< the IPv4 addresses it takes UDP on ("10.0.0.21"), as it announced them
};

/// A sample as received: the payload as serialized (CDR encapsulation included).
struct ProbeSample
{
    std::vector<uint8_t> payload;
    uint64_t source_ns = 0;    ///< the writer's source timestamp
    uint64_t received_ns = 0;  ///< when this process took it (cpm::get_time_ns)
    std::string instance;      ///< the DDS instance handle as hex (the key's hash); "" for an unkeyed topic
};

/// A participant of its own that listens to discovery from its first moment. Not thread-safe:
/// one thread calls it.
class TopicProbe
{
public:
    /// Throws cpm::Error when the participant cannot be created.
    explicit TopicProbe(const ParticipantOptions& options = ParticipantOptions::from_init());
    ~TopicProbe();
    TopicProbe(const TopicProbe&) = delete;
    TopicProbe& operator=(const TopicProbe&) = delete;

    /// The topics with at least one writer or reader (other than this probe's), by name.
    std::vector<TopicInfo> topics() const;
    /// The names of the other participants discovered on the domain (and not gone since).
    std::vector<std::string> participants() const;
    /// The same participants with the addresses they announced (which host each is on).
    std::vector<ParticipantSeen> participants_seen() const;
    /// Waits up to `timeout` for a writer of `topic` and subscribes to it as that writer offers
    /// (as reliable and as durable), receiving raw payloads. False when no writer appeared.
    /// Throws cpm::Error when the reader cannot be created.
    bool subscribe(const std::string& topic, std::chrono::milliseconds timeout);
    /// The samples received since the last call, oldest first, waiting up to `timeout` for one.
    std::vector<ProbeSample> take(std::chrono::milliseconds timeout);

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm::rtdb
