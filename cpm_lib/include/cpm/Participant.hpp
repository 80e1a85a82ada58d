#pragma once
#include <cpm/Discovery.hpp>
#include <cpm/Error.hpp>
#include <cpm/Realtime.hpp>

#include <chrono>
#include <memory>
#include <string>
#include <vector>

namespace eprosima::fastdds::dds {
class DomainParticipant;
}  // namespace eprosima::fastdds::dds

namespace cpm {
namespace detail {
class ParticipantCore;
}

/// How a participant reaches others. The default reaches this host only: UDPv4 bound to
/// 127.0.0.1 plus shared memory, unicast discovery, no multicast. Naming interfaces,
/// initial peers or a discovery server opens it to a network.
struct ParticipantOptions
{
    int domain_id = -1;                      ///< 0..232; -1: cpm::init's --dds_domain / CPM_DOMAIN_ID
    std::string name;                        ///< participant name; empty: cpm::init's node id
    std::vector<std::string> interfaces;     ///< IPv4 addresses or interface names to use besides 127.0.0.1
    std::vector<std::string> initial_peers;  ///< "host" or "host:port" of remote participants (unicast discovery)
    std::string discovery_server;            ///< "host:port" of a Fast DDS discovery server (server id 0)
    bool shared_memory = true;               ///< use shared memory between processes on this host
    int max_initial_peers_range = 32;        ///< participants per host that unicast discovery probes
    /// How long the others wait for this participant once it falls silent (its process killed,
    /// frozen or cut off) before they drop it, its readers and writers; 1s..1h. It announces
    /// itself every third of it (at most once a second). Shorter finds a dead node sooner, and
    /// drops a live one that is starved of CPU or network for that long.
    std::chrono::milliseconds lease{10'000};
    /// A node's security folder (cpm security add-node): the participant joins a secured lab
    /// with that node's identity and permissions. Empty: unsecured.
    std::string security;
    /// Told of every participant, writer and reader found, changed or gone, from the first
    /// moment (see DiscoveryCallback for its thread). For tools such as cpm_history. It is
    /// called until the participant is deleted, which is when its last reader or writer goes:
    /// what it refers to must live that long.
    DiscoveryCallback on_discovery;
    /// --realtime: Fast DDS allocates its tables of remote participants, readers and writers
    /// for a lab up front (16 participants with 32 readers and 32 writers each; beyond, they grow), and
    /// its send buffers, so discovery during a run allocates less.
    Realtime realtime = Realtime::off;

    /// The options given by cpm::init (or the environment).
    static ParticipantOptions from_init();
};

/// Owns one Fast DDS domain participant with its publisher and subscriber. Movable, not
/// copyable. Readers and writers created on it keep it alive until they are gone.
/// Throws cpm::Error when the options are invalid or Fast DDS refuses them.
class Participant
{
public:
    explicit Participant(const ParticipantOptions& options = ParticipantOptions::from_init());
    ~Participant();
    Participant(Participant&&) noexcept;
    Participant& operator=(Participant&&) noexcept;
    Participant(const Participant&) = delete;
    Participant& operator=(const Participant&) = delete;

    /// The process-wide participant that readers and writers use when none is given;
    /// created on first use from cpm::init's settings. Thread-safe. Deleted at exit (Fast DDS
    /// then removes its shared memory) once the last reader or writer on it is gone; asked for
    /// while the process exits, throws cpm::Error.
    static Participant& default_participant();

    int domain_id() const;
    /// Whether it joined with DDS Security (ParticipantOptions::security).
    bool secured() const;
    /// The Fast DDS participant, for what cpm does not wrap. Owned by this object.
    eprosima::fastdds::dds::DomainParticipant* native() const;
    /// Shared with readers and writers; not part of the stable interface.
    const std::shared_ptr<detail::ParticipantCore>& core() const { return core_; }

private:
    std::shared_ptr<detail::ParticipantCore> core_;
};

}  // namespace cpm
