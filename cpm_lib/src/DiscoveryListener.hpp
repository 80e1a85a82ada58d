#pragma once
// Fast DDS's discovery callbacks turned into cpm::DiscoveryEvent for ParticipantOptions::on_discovery.
#include <cpm/Discovery.hpp>

#include <fastdds/dds/domain/DomainParticipantListener.hpp>

#include <optional>

namespace cpm::detail {

class DiscoveryListener final : public eprosima::fastdds::dds::DomainParticipantListener
{
public:
    explicit DiscoveryListener(DiscoveryCallback callback) : callback_(std::move(callback)) {}

    void on_participant_discovery(eprosima::fastdds::dds::DomainParticipant*, eprosima::fastrtps::rtps::ParticipantDiscoveryInfo&& info) override;
    void on_publisher_discovery(eprosima::fastdds::dds::DomainParticipant*, eprosima::fastrtps::rtps::WriterDiscoveryInfo&& info) override;
    void on_subscriber_discovery(eprosima::fastdds::dds::DomainParticipant*, eprosima::fastrtps::rtps::ReaderDiscoveryInfo&& info) override;

private:
    void tell(const DiscoveryEvent& e) noexcept;
    template <class ProxyData>
    void tell_endpoint(const ProxyData& info, std::optional<DiscoveryEvent::Kind> kind);
    DiscoveryCallback callback_;
};

}  // namespace cpm::detail
