#include "ParticipantCore.hpp"

#include "DiscoveryListener.hpp"

#include <cpm/Error.hpp>
#include <cpm/init.hpp>

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/log/Log.hpp>
#include <fastdds/dds/log/StdoutErrConsumer.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <fastdds/rtps/attributes/ServerAttributes.h>
#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastdds/rtps/transport/shared_mem/SharedMemTransportDescriptor.h>
#include <fastrtps/utils/IPLocator.h>
#include <openssl/crypto.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <dirent.h>
#include <fcntl.h>
#include <mutex>
#include <optional>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>
#include <vector>

namespace cpm {
namespace detail {

namespace dds = eprosima::fastdds::dds;
namespace rtps = eprosima::fastrtps::rtps;

namespace {

// "a.b.c.d" or "a.b.c.d:port" as a UDPv4 locator; port 0 means "the well-known ports".
rtps::Locator_t udp_locator(const std::string& text, const std::string& what)
{
    std::string host = text;
    uint32_t port = 0;
    const auto colon = text.rfind(':');
    if (colon != std::string::npos) {
        host = text.substr(0, colon);
        const std::string port_text = text.substr(colon + 1);
        char* end = nullptr;
        const long value = std::strtol(port_text.c_str(), &end, 10);
        if (port_text.empty() || *end != '\0' || value < 1 || value > 65535) {
            throw Error(what + " '" + text + "': port '" + port_text + "' is not a number in 1..65535");
        }
        port = static_cast<uint32_t>(value);
    }
    if (!rtps::IPLocator::isIPv4(host)) {
        throw Error(what + " '" + text + "': '" + host + "' is not an IPv4 address (use a.b.c.d or a.b.c.d:port)");
    }
    rtps::Locator_t locator;
    locator.kind = LOCATOR_KIND_UDPv4;
    rtps::IPLocator::setIPv4(locator, host);
    locator.port = port;
    return locator;
}

/// Fast DDS's shared-memory ports of a domain: 7400 + 250 * domain + offsets below 250.
bool port_of_domain(unsigned port, int domain_id)
{
    const unsigned first = 7400u + 250u * static_cast<unsigned>(domain_id);
    return port >= first && port < first + 250u;
}

/// Removes the markers (below) of this domain's ports whose files are gone: a port that its
/// process released on a clean exit needs no marker, and none may pile up in /dev/shm.
void forget_gone_ports(int domain_id)
{
    DIR* dir = ::opendir("/dev/shm");
    if (dir == nullptr) return;
    while (const dirent* entry = ::readdir(dir)) {
        unsigned port = 0;
        char tail = 0;
        if (std::sscanf(entry->d_name, "cpm_dead_fastrtps_port%u%c", &port, &tail) != 1 || !port_of_domain(port, domain_id)) continue;
        struct stat lock {};
        if (::stat(("/dev/shm/fastrtps_port" + std::to_string(port) + "_el").c_str(), &lock) != 0) {
            ::unlink((std::string("/dev/shm/") + entry->d_name).c_str());
        }
    }
    ::closedir(dir);
}

/// The locks of the shared-memory ports of this domain whose listening process died in the last
/// few seconds, held while a participant is made. Fast DDS gives a new participant the first port
/// it can open and takes over a dead process's port at once, but the dead one's peers keep
/// sending to their handle of the old port until Fast DDS's port watchdog (once a second)
/// notices, one to two seconds: a node started again after kill -9 heard nothing from its peers
/// for that long. A dead port whose lock is held looks alive, so Fast DDS passes it by and the
/// new node gets a fresh port. A port's listener holds an flock on /dev/shm/fastrtps_port<N>_el
/// while it lives; a marker file (cpm_dead_fastrtps_port<N>) says since when a port is seen dead,
/// and after kRecently it is left to Fast DDS to take over (its peers have let go of it by then,
/// and ports of dead processes must not pile up past Fast DDS's 100 tries).
class DeadPortsHeld
{
public:
    explicit DeadPortsHeld(int domain_id)
    {
        forget_gone_ports(domain_id);
        DIR* dir = ::opendir("/dev/shm");
        if (dir == nullptr) return;
        const auto now = std::chrono::system_clock::now();
        while (const dirent* entry = ::readdir(dir)) {
            unsigned port = 0;
            char tail[4] = {};
            if (std::sscanf(entry->d_name, "fastrtps_port%u%3s", &port, tail) != 2 || std::string(tail) != "_el" ||
                !port_of_domain(port, domain_id))
                continue;
            const std::string lock = std::string("/dev/shm/") + entry->d_name;
            const std::string marker = "/dev/shm/cpm_dead_fastrtps_port" + std::to_string(port);
            const int fd = ::open(lock.c_str(), O_RDONLY | O_CLOEXEC);
            if (fd < 0) continue;
            if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {  // a live port
                ::close(fd);
                ::unlink(marker.c_str());
                continue;
            }
            struct stat seen {};
            if (::stat(marker.c_str(), &seen) != 0) {
                const int m = ::open(marker.c_str(), O_CREAT | O_WRONLY | O_CLOEXEC, 0644);
                if (m >= 0) ::close(m);
                held_.push_back(fd);
            } else if (now - std::chrono::system_clock::from_time_t(seen.st_mtime) < kRecently) {
                held_.push_back(fd);
            } else {
                ::unlink(marker.c_str());  // long dead: Fast DDS may take it over now
                ::close(fd);
            }
        }
        ::closedir(dir);
    }
    ~DeadPortsHeld()
    {
        for (int fd : held_) ::close(fd);  // closing releases the lock
    }
    DeadPortsHeld(const DeadPortsHeld&) = delete;
    DeadPortsHeld& operator=(const DeadPortsHeld&) = delete;

private:
    static constexpr std::chrono::seconds kRecently{10};
    std::vector<int> held_;
};

}  // namespace

namespace {

constexpr uint32_t kUdpSocketBufferBytes = 1024 * 1024;

/// UDPv4 on loopback unless the options open the network (interfaces, peers, a discovery server);
/// with interfaces named, on those (and loopback) only.
std::shared_ptr<eprosima::fastdds::rtps::UDPv4TransportDescriptor> udp_transport(const ParticipantOptions& options)
{
    auto udp = std::make_shared<eprosima::fastdds::rtps::UDPv4TransportDescriptor>();
    udp->maxInitialPeersRange = static_cast<uint32_t>(std::max(options.max_initial_peers_range, 1));
    // Between hosts the data goes over UDP: the kernel's default socket buffers (208 KiB) drop
    // part of a reliable writer's window sent at once, repaired only at heartbeat pace. 1 MiB
    // (capped by net.core.rmem_max/wmem_max) carried 1 KiB samples 25-40 % faster on loopback,
    // more did no better (bench/throughput, 2026-12-04).
    udp->sendBufferSize = kUdpSocketBufferBytes;
    udp->receiveBufferSize = kUdpSocketBufferBytes;
    const bool open_network = !options.interfaces.empty() || !options.initial_peers.empty() ||
                              !options.discovery_server.empty();
    for (const auto& name : options.interfaces) check_local_interface(name, "participant option interfaces");
    if (!open_network || !options.interfaces.empty()) {
        udp->interfaceWhiteList.push_back("127.0.0.1");
        for (const auto& name : options.interfaces) udp->interfaceWhiteList.push_back(name);
    }
    return udp;
}

std::shared_ptr<eprosima::fastdds::rtps::SharedMemTransportDescriptor> shared_memory_transport()
{
    // Fast DDS's defaults (512 KiB, 512 messages) overflow when a reliable writer sends a
    // window of samples at once; every dropped sample then waits for a repair round
    // (bench/throughput: 1 KiB keep-all went from ~1-8k to ~75k samples/s).
    auto shm = std::make_shared<eprosima::fastdds::rtps::SharedMemTransportDescriptor>();
    shm->segment_size(4 * 1024 * 1024);
    shm->port_queue_capacity(2048);
    // A process started again after a crash gets its predecessor's port; opening it waits
    // this long for the dead listeners before making the port anew, and its peers' sends go
    // nowhere meanwhile (Fast DDS's 1 s made a restarted node deaf for about a second). A
    // live listener that misses the check only re-attaches to the new port.
    shm->healthy_check_timeout_ms(200);
    return shm;
}

}  // namespace

dds::DomainParticipantQos participant_qos(const ParticipantOptions& options)
{
    dds::DomainParticipantQos qos = dds::PARTICIPANT_QOS_DEFAULT;
    qos.name(options.name.empty() ? init_settings().node_id : options.name);

    // Never Fast DDS's built-in transports: they multicast discovery on every interface.
    auto& transport = qos.transport();
    transport.use_builtin_transports = false;
    if (options.shared_memory) transport.user_transports.push_back(shared_memory_transport());
    transport.user_transports.push_back(udp_transport(options));

    auto& builtin = qos.wire_protocol().builtin;
    const auto lease = checked_lease(options.lease, "participant option lease");
    const auto announce = std::min<std::chrono::milliseconds>(lease / 3, std::chrono::seconds(1));
    auto duration = [](std::chrono::milliseconds ms) {
        return eprosima::fastrtps::Duration_t{int32_t(ms.count() / 1000), uint32_t(ms.count() % 1000 * 1'000'000)};
    };
    builtin.discovery_config.leaseDuration = duration(lease);
    builtin.discovery_config.leaseDuration_announcementperiod = duration(announce);
    builtin.discovery_config.initial_announcements.count = 5;
    builtin.discovery_config.initial_announcements.period = {0, 100'000'000};
    qos.wire_protocol().participant_id = -1;
    if (options.realtime != Realtime::off) {
        auto& allocation = qos.allocation();
        allocation.participants = eprosima::fastrtps::ResourceLimitedContainerConfig(16);
        allocation.readers = eprosima::fastrtps::ResourceLimitedContainerConfig(32);
        allocation.writers = eprosima::fastrtps::ResourceLimitedContainerConfig(32);
        allocation.send_buffers.preallocated_number = 4;
    }

    if (!options.discovery_server.empty()) {
        // A super client: it hears of every endpoint, not only of those matching its own (a
        // recording history, the monitor and `cpm topic list` subscribe to what they discover).
        builtin.discovery_config.discoveryProtocol = rtps::DiscoveryProtocol_t::SUPER_CLIENT;
        rtps::RemoteServerAttributes server;
        rtps::get_server_client_default_guidPrefix(0, server.guidPrefix);
        rtps::Locator_t locator = udp_locator(options.discovery_server, "discovery server");
        if (locator.port == 0) locator.port = 11811;  // Fast DDS's default server port
        server.metatrafficUnicastLocatorList.push_back(locator);
        builtin.discovery_config.m_DiscoveryServers.push_back(server);
    } else if (options.interfaces.empty() || !options.initial_peers.empty()) {
        // Unicast discovery only: an explicit (any-address, well-known-port) metatraffic
        // locator stops Fast DDS from adding its multicast one; peers are this host plus
        // the ones named.
        rtps::Locator_t any;
        any.kind = LOCATOR_KIND_UDPv4;
        builtin.metatrafficUnicastLocatorList.push_back(any);
        builtin.initialPeersList.push_back(udp_locator("127.0.0.1", "initial peer"));
        for (const auto& peer : options.initial_peers) {
            builtin.initialPeersList.push_back(udp_locator(peer, "initial peer"));
        }
    }
    // else: interfaces named, no peers, no server: standard multicast discovery on them.
    if (!options.security.empty()) {
        for (const auto& [name, value] : security::participant_properties(security::node_files(options.security))) {
            qos.properties().properties().emplace_back(name, value);
        }
    }
    return qos;
}

namespace {

/// Fast DDS prints its own log on stdout by default, into what a program writes there for
/// others to read (`cpm topic echo --json`, the "device: …" line `cpm vehicle sim` waits for).
/// Every message goes to stderr instead, once per process.
void send_fast_dds_log_to_stderr()
{
    static std::once_flag once;
    std::call_once(once, [] {
        auto consumer = std::make_unique<dds::StdoutErrConsumer>();
        consumer->stderr_threshold(dds::Log::Kind::Info);
        dds::Log::ClearConsumers();
        dds::Log::RegisterConsumer(std::move(consumer));
    });
}

}  // namespace

ParticipantCore::ParticipantCore(const ParticipantOptions& options)
    : factory_(dds::DomainParticipantFactory::get_shared_instance()),
      domain_id_(checked_domain_id(options.domain_id >= 0 ? options.domain_id : init_settings().domain_id,
                                   "participant option domain_id"))
{
    send_fast_dds_log_to_stderr();
    dds::DomainParticipantQos qos = participant_qos(options);
    if (!options.security.empty()) {
        // OpenSSL frees itself at exit, while Fast DDS's receive threads may still decrypt a
        // message (the default participant lives until the process ends): a secured node killed
        // by SIGSEGV on its way out, about one run in two (cpm lab run with security:). A process
        // that uses DDS Security leaves OpenSSL to the end of the process instead.
        OPENSSL_init_crypto(OPENSSL_INIT_NO_ATEXIT, nullptr);
    }
    std::optional<DeadPortsHeld> dead_ports;
    if (options.shared_memory) dead_ports.emplace(domain_id_);
    if (options.on_discovery) discovery_ = std::make_unique<DiscoveryListener>(options.on_discovery);
    participant_ = factory_->create_participant(static_cast<dds::DomainId_t>(domain_id_), qos, discovery_.get(),
                                                dds::StatusMask::none());
    dead_ports.reset();
    if (participant_ == nullptr) {
        throw Error("cannot create a DDS participant on domain " + std::to_string(domain_id_) +
                    (options.security.empty() ? " (Fast DDS refused the transport or discovery settings; see its log above)"
                                              : " with the security folder " + options.security +
                                                    " (Fast DDS refused its certificate, key, governance or permissions: an "
                                                    "expired certificate, files of another lab, a signature that does not "
                                                    "verify; see its log above)"));
    }
    // Past this point a failure deletes the participant before the listener it calls goes.
    auto undo = [&] {
        participant_->delete_contained_entities();
        factory_->delete_participant(participant_);
    };
    try {
        if (!options.security.empty()) security_ = security::node_files(options.security);
    } catch (...) {
        undo();
        throw;
    }
    publisher_ = participant_->create_publisher(dds::PUBLISHER_QOS_DEFAULT);
    subscriber_ = participant_->create_subscriber(dds::SUBSCRIBER_QOS_DEFAULT);
    if (publisher_ == nullptr || subscriber_ == nullptr) {
        undo();
        throw Error("cannot create the DDS publisher/subscriber on domain " + std::to_string(domain_id_));
    }
}

ParticipantCore::~ParticipantCore()
{
    participant_->delete_contained_entities();
    factory_->delete_participant(participant_);  // Fast DDS unlinks this participant's shared memory here
    forget_gone_ports(domain_id_);
}

dds::Topic* ParticipantCore::acquire_topic(const std::string& name, MakeTypeSupport make_type, const char* role)
{
    if (name.empty()) throw Error(std::string(role) + ": the topic name is empty");
    dds::TypeSupport type(make_type());
    const std::string type_name = type.get_type_name();

    std::lock_guard<std::mutex> lock(topics_mutex_);
    auto found = topics_.find(name);
    if (found != topics_.end()) {
        const std::string existing = found->second.topic->get_type_name();
        if (existing != type_name) {
            throw Error(std::string(role) + " on topic '" + name + "' with type '" + type_name +
                        "': the topic already has type '" + existing + "' in this participant");
        }
        ++found->second.users;
        return found->second.topic;
    }
    if (participant_->find_type(type_name).empty()) {
        // Without type information in discovery, Cyclone DDS and others can match us.
        type->auto_fill_type_information(false);
        type->auto_fill_type_object(false);
        if (type.register_type(participant_) != ReturnCode_t::RETCODE_OK) {
            throw Error(std::string(role) + " on topic '" + name + "': cannot register type '" + type_name + "'");
        }
    }
    dds::Topic* topic = participant_->create_topic(name, type_name, dds::TOPIC_QOS_DEFAULT);
    if (topic == nullptr) {
        throw Error(std::string(role) + ": cannot create topic '" + name + "' of type '" + type_name + "'");
    }
    topics_.emplace(name, TopicUse{topic, 1});
    return topic;
}

void ParticipantCore::release_topic(dds::Topic* topic)
{
    std::lock_guard<std::mutex> lock(topics_mutex_);
    auto found = topics_.find(topic->get_name());
    if (found == topics_.end() || --found->second.users > 0) return;
    participant_->delete_topic(topic);
    topics_.erase(found);
}

}  // namespace detail

ParticipantOptions ParticipantOptions::from_init()
{
    const InitSettings settings = init_settings();
    ParticipantOptions options;
    options.domain_id = settings.domain_id;
    options.name = settings.node_id;
    options.interfaces = settings.interfaces;
    options.initial_peers = settings.initial_peers;
    options.discovery_server = settings.discovery_server;
    options.security = settings.security;
    options.shared_memory = settings.shared_memory;
    options.lease = settings.lease;
    options.realtime = settings.realtime;
    return options;
}

Participant::Participant(const ParticipantOptions& options)
    : core_(std::make_shared<detail::ParticipantCore>(options))
{
}

Participant::~Participant() = default;
Participant::Participant(Participant&&) noexcept = default;
Participant& Participant::operator=(Participant&&) noexcept = default;

namespace {
std::atomic<bool> default_participant_gone{false};
}

Participant& Participant::default_participant()
{
    // Destroyed at exit, so that Fast DDS unlinks its shared-memory segment and port files
    // (4 MB of RAM-backed /dev/shm each, left behind by every process while this was leaked).
    // Readers and writers in static objects that outlive it hold the participant's core, which
    // goes with the last of them.
    static Participant instance(ParticipantOptions::from_init());
    // Registered after the instance exists, so this runs before it is destroyed: from then on a
    // first use (a static destructor's or another thread's first log message) is refused, not a
    // use of a destroyed object.
    static const bool registered = std::atexit([] { default_participant_gone.store(true); }) == 0;
    (void)registered;
    if (default_participant_gone.load()) throw Error("the process is exiting: its default participant is gone");
    return instance;
}

int Participant::domain_id() const { return core_->domain_id(); }

bool Participant::secured() const { return core_->secured(); }

eprosima::fastdds::dds::DomainParticipant* Participant::native() const { return core_->participant(); }

}  // namespace cpm
