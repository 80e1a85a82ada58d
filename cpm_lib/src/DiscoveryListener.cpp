#include "DiscoveryListener.hpp"

#include "log_internal.hpp"

#include <cstring>
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

/// A writer's or reader's topic, type and the QoS others match against.
template <class ProxyData>
void endpoint(DiscoveryEvent& e, const ProxyData& info)
{
    e.guid = guid_bytes(info.guid());
    e.topic = info.topicName().to_string();
    e.type_name = info.typeName().to_string();
    e.keyed = info.topicKind() == rtps::WITH_KEY;
    e.reliable = info.m_qos.m_reliability.kind == dds::RELIABLE_RELIABILITY_QOS;
    e.transient_local = info.m_qos.m_durability.kind != dds::VOLATILE_DURABILITY_QOS;
}

}  // namespace

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
    DiscoveryEvent e;
    switch (info.status) {
    case rtps::WriterDiscoveryInfo::DISCOVERED_WRITER: e.kind = DiscoveryEvent::Kind::writer_found; break;
    case rtps::WriterDiscoveryInfo::CHANGED_QOS_WRITER: e.kind = DiscoveryEvent::Kind::writer_changed; break;
    case rtps::WriterDiscoveryInfo::REMOVED_WRITER: e.kind = DiscoveryEvent::Kind::writer_gone; break;
    default: return;
    }
    endpoint(e, info.info);
    tell(e);
}

void DiscoveryListener::on_subscriber_discovery(dds::DomainParticipant*, rtps::ReaderDiscoveryInfo&& info)
{
    DiscoveryEvent e;
    switch (info.status) {
    case rtps::ReaderDiscoveryInfo::DISCOVERED_READER: e.kind = DiscoveryEvent::Kind::reader_found; break;
    case rtps::ReaderDiscoveryInfo::CHANGED_QOS_READER: e.kind = DiscoveryEvent::Kind::reader_changed; break;
    case rtps::ReaderDiscoveryInfo::REMOVED_READER: e.kind = DiscoveryEvent::Kind::reader_gone; break;
    default: return;
    }
    endpoint(e, info.info);
    tell(e);
}

}  // namespace cpm::detail
