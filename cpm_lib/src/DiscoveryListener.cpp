#include "DiscoveryListener.hpp"

#include "log_internal.hpp"

#include <cstring>
#include <optional>
#include <sstream>

namespace cpm::detail {

namespace dds = eprosima::fastdds::dds;
namespace rtps = eprosima::fastrtps::rtps;

namespace {

std::array<uint8_t, 16> guid_bytes(const rtps::GUID_t& guid)
{
    std::array<uint8_t, 16> out{};
    std::memcpy(out.data(), guid.guidPrefix.value, 12);
    std::memcpy(out.data() + 12, guid.entityId.value, 4);
    return out;
}

template <class List>
std::vector<std::string> locator_texts(const List& locators)
{
    std::vector<std::string> out;
    for (const auto& l : locators) {
        std::ostringstream text;
        text << l;
        out.push_back(text.str());
    }
    return out;
}

}  // namespace

/// A writer's or reader's event (none for statuses cpm does not act on): its topic, type and
/// the QoS others match against.
template <class ProxyData>
void DiscoveryListener::tell_endpoint(const ProxyData& info, std::optional<DiscoveryEvent::Kind> kind)
{
    if (!kind) return;
    DiscoveryEvent e;
    e.kind = *kind;
    e.guid = guid_bytes(info.guid());
    e.topic = info.topicName().to_string();
    e.type_name = info.typeName().to_string();
    e.keyed = info.topicKind() == rtps::WITH_KEY;
    e.reliable = info.m_qos.m_reliability.kind == dds::RELIABLE_RELIABILITY_QOS;
    e.transient_local = info.m_qos.m_durability.kind != dds::VOLATILE_DURABILITY_QOS;
    tell(e);
}

void DiscoveryListener::tell(const DiscoveryEvent& e) noexcept
{
    // Never let an exception into Fast DDS's discovery thread.
    try {
        callback_(e);
    } catch (const std::exception& ex) {
        log_error(std::string("discovery callback: ") + ex.what());
    } catch (...) {
        log_error("discovery callback: an exception that is no std::exception");
    }
}

void DiscoveryListener::on_participant_discovery(dds::DomainParticipant*, rtps::ParticipantDiscoveryInfo&& info)
{
    DiscoveryEvent e;
    switch (info.status) {
    case rtps::ParticipantDiscoveryInfo::DISCOVERED_PARTICIPANT: e.kind = DiscoveryEvent::Kind::participant_found; break;
    case rtps::ParticipantDiscoveryInfo::REMOVED_PARTICIPANT:
    case rtps::ParticipantDiscoveryInfo::DROPPED_PARTICIPANT: e.kind = DiscoveryEvent::Kind::participant_gone; break;
    default: return;  // changed or ignored: nothing a cpm program acts on
    }
    e.guid = guid_bytes(info.info.m_guid);
    e.participant_name = info.info.m_participantName.to_string();
    e.unicast_locators = locator_texts(info.info.metatraffic_locators.unicast);
    for (auto& l : locator_texts(info.info.default_locators.unicast)) e.unicast_locators.push_back(std::move(l));
    e.multicast_locators = locator_texts(info.info.metatraffic_locators.multicast);
    for (auto& l : locator_texts(info.info.default_locators.multicast)) e.multicast_locators.push_back(std::move(l));
    tell(e);
}

void DiscoveryListener::on_publisher_discovery(dds::DomainParticipant*, rtps::WriterDiscoveryInfo&& info)
{
    using W = rtps::WriterDiscoveryInfo;
    using K = DiscoveryEvent::Kind;
    tell_endpoint(info.info, info.status == W::DISCOVERED_WRITER    ? std::optional(K::writer_found)
                             : info.status == W::CHANGED_QOS_WRITER ? std::optional(K::writer_changed)
                             : info.status == W::REMOVED_WRITER     ? std::optional(K::writer_gone)
                                                                    : std::nullopt);
}

void DiscoveryListener::on_subscriber_discovery(dds::DomainParticipant*, rtps::ReaderDiscoveryInfo&& info)
{
    using R = rtps::ReaderDiscoveryInfo;
    using K = DiscoveryEvent::Kind;
    tell_endpoint(info.info, info.status == R::DISCOVERED_READER    ? std::optional(K::reader_found)
                             : info.status == R::CHANGED_QOS_READER ? std::optional(K::reader_changed)
                             : info.status == R::REMOVED_READER     ? std::optional(K::reader_gone)
                                                                    : std::nullopt);
}

}  // namespace cpm::detail
