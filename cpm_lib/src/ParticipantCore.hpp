#pragma once
#include <cpm/Error.hpp>
#include <cpm/Participant.hpp>
#include <cpm/Security.hpp>
#include <cpm/detail/TypeSupport.hpp>

#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/domain/qos/DomainParticipantQos.hpp>

#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

namespace eprosima::fastdds::dds {
class DomainParticipant;
class DomainParticipantListener;
class Publisher;
class Subscriber;
class Topic;
}  // namespace eprosima::fastdds::dds

namespace cpm::detail {

/// The DDS participant QoS cpm uses for these options (this host only by default).
/// Throws cpm::Error naming a malformed peer, server or domain id.
eprosima::fastdds::dds::DomainParticipantQos participant_qos(const ParticipantOptions& options);

/// One Fast DDS participant with one publisher and one subscriber, and the topics that
/// readers and writers share (a participant may create each topic name only once).
class ParticipantCore
{
public:
    explicit ParticipantCore(const ParticipantOptions& options);
    ~ParticipantCore();

    eprosima::fastdds::dds::DomainParticipant* participant() const { return participant_; }
    eprosima::fastdds::dds::Publisher* publisher() const { return publisher_; }
    eprosima::fastdds::dds::Subscriber* subscriber() const { return subscriber_; }
    int domain_id() const { return domain_id_; }
    /// Empty when this participant may publish (or subscribe) the topic: always unsecured, else
    /// as its permissions say; otherwise why not, naming the topic and the rule.
    std::string denied(const std::string& topic, bool publish) const
    {
        return security_ ? security::why_not_allowed(*security_, topic, publish) : std::string();
    }
    bool secured() const { return security_.has_value(); }

    /// The topic `name` of the given type, created on first use; throws cpm::Error when the
    /// name is empty or the topic already exists here with another type. `role` (Reader,
    /// Writer, ...) names the caller in messages. Pair with release_topic.
    eprosima::fastdds::dds::Topic* acquire_topic(const std::string& name, MakeTypeSupport make_type,
                                                 const char* role);
    void release_topic(eprosima::fastdds::dds::Topic* topic);

private:
    std::shared_ptr<eprosima::fastdds::dds::DomainParticipantFactory> factory_;
    int domain_id_;
    eprosima::fastdds::dds::DomainParticipant* participant_ = nullptr;
    eprosima::fastdds::dds::Publisher* publisher_ = nullptr;
    eprosima::fastdds::dds::Subscriber* subscriber_ = nullptr;
    std::mutex topics_mutex_;
    struct TopicUse
    {
        eprosima::fastdds::dds::Topic* topic;
        int users;
    };
    std::map<std::string, TopicUse> topics_;
    std::optional<security::NodeFiles> security_;
    std::unique_ptr<eprosima::fastdds::dds::DomainParticipantListener> discovery_;  ///< outlives participant_
};

/// Throws cpm::Error, naming the topic, when a secured participant may not have this endpoint:
/// its permissions do not grant the topic, or data sharing was asked for (Fast DDS refuses data
/// sharing with DDS Security). `role` (Writer, Reader, …) names the caller.
inline void check_secured_endpoint(const ParticipantCore& participant, const std::string& topic, bool publish, bool data_sharing,
                                   const std::string& role)
{
    if (!participant.secured()) return;
    if (data_sharing) {
        throw Error(role + " on topic '" + topic + "': data_sharing and DDS Security (--security) cannot be used together "
                    "(Fast DDS refuses data sharing on a secured participant); leave data_sharing off");
    }
    if (auto why = participant.denied(topic, publish); !why.empty()) throw Error(role + " on topic '" + topic + "': " + why);
}

/// A topic held for one reader or writer: acquired on construction (throws like
/// ParticipantCore::acquire_topic), released on destruction. Keeps the participant alive.
class TopicLease
{
public:
    TopicLease(std::shared_ptr<ParticipantCore> participant, const std::string& name, MakeTypeSupport make_type,
               const char* role)
        : participant_(std::move(participant)), topic_(participant_->acquire_topic(name, make_type, role)), name_(name)
    {
    }
    ~TopicLease() { participant_->release_topic(topic_); }
    TopicLease(const TopicLease&) = delete;
    TopicLease& operator=(const TopicLease&) = delete;

    ParticipantCore& participant() const { return *participant_; }
    eprosima::fastdds::dds::Topic* topic() const { return topic_; }
    const std::string& name() const { return name_; }

private:
    std::shared_ptr<ParticipantCore> participant_;
    eprosima::fastdds::dds::Topic* topic_;
    std::string name_;
};

}  // namespace cpm::detail
