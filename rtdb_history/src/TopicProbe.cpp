#include <cpm/rtdb/TopicProbe.hpp>

#include <cpm/Error.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/rtdb/IdlDecoder.hpp>

#include "RawType.hpp"

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/Topic.hpp>

#include <condition_variable>
#include <deque>
#include <map>
#include <mutex>

namespace cpm::rtdb {

namespace dds = eprosima::fastdds::dds;
namespace rtps = eprosima::fastrtps::rtps;

namespace {

struct Seen : RawEndpoint
{
    bool is_writer = false;
};

}  // namespace

struct TopicProbe::Impl : public dds::DataReaderListener
{
    // Discovery, filled by Fast DDS's threads.
    mutable std::mutex discovery_mutex;
    std::condition_variable discovered;
    std::map<rtps::GUID_t, Seen> endpoints;
    std::map<rtps::GuidPrefix_t, ParticipantSeen> participants_seen;

    // Samples, filled by the reader's listener (which holds the reader's lock: only our mutex
    // is taken under it, and nothing DDS is called under our mutex).
    std::mutex samples_mutex;
    std::condition_variable arrived;
    std::deque<ProbeSample> samples;

    std::unique_ptr<Participant> participant;
    dds::Subscriber* subscriber = nullptr;
    dds::Topic* topic = nullptr;
    dds::DataReader* reader = nullptr;

    void on_discovery(const DiscoveryEvent& e)
    {
        std::lock_guard lock(discovery_mutex);
        const rtps::GUID_t guid = fast_dds_guid(e);
        switch (e.kind) {
        case DiscoveryEvent::Kind::participant_found: {
            ParticipantSeen& p = participants_seen[guid.guidPrefix];
            p.name = e.participant_name.empty() ? "(unnamed)" : e.participant_name;
            p.addresses.clear();
            for (const auto& l : e.unicast_locators) {  // "UDPv4:[10.0.0.21]:7411"
                const auto open = l.find('['), close = l.find(']');
                if (l.rfind("UDPv4:", 0) == 0 && open != std::string::npos && close > open) p.addresses.push_back(l.substr(open + 1, close - open - 1));
            }
            return;
        }
        case DiscoveryEvent::Kind::participant_gone:
            participants_seen.erase(guid.guidPrefix);
            std::erase_if(endpoints, [&](const auto& p) { return p.first.guidPrefix == guid.guidPrefix; });
            return;
        case DiscoveryEvent::Kind::writer_gone:
        case DiscoveryEvent::Kind::reader_gone: endpoints.erase(guid); return;
        default:  // found or changed
            Seen seen;
            static_cast<RawEndpoint&>(seen) = raw_endpoint(e);
            seen.is_writer = e.kind == DiscoveryEvent::Kind::writer_found || e.kind == DiscoveryEvent::Kind::writer_changed;
            endpoints[guid] = seen;
            discovered.notify_all();
        }
    }

    void on_data_available(dds::DataReader* r) override
    {
        RawSample raw;
        dds::SampleInfo info;
        while (r->take_next_sample(&raw, &info) == ReturnCode_t::RETCODE_OK) {
            if (!info.valid_data) continue;
            ProbeSample s;
            s.payload = std::move(raw.bytes);
            s.source_ns = source_time_ns(info);
            s.received_ns = get_time_ns();
            if (info.instance_handle.isDefined()) {
                static const char* const kHex = "0123456789abcdef";
                for (size_t i = 0; i < 16; ++i) {
                    const auto b = info.instance_handle.value[i];
                    s.instance += kHex[b >> 4];
                    s.instance += kHex[b & 15];
                }
            }
            std::lock_guard lock(samples_mutex);
            samples.push_back(std::move(s));
            arrived.notify_all();
        }
    }

    std::string name_of(const rtps::GuidPrefix_t& prefix) const
    {
        if (auto n = participants_seen.find(prefix); n != participants_seen.end()) return n->second.name;
        return guid_prefix_text(prefix);
    }
};

TopicProbe::TopicProbe(const ParticipantOptions& options) : impl_(std::make_unique<Impl>())
{
    ParticipantOptions o = options;
    if (o.name.empty()) o.name = "cpm_topic_probe";
    o.on_discovery = [impl = impl_.get()](const DiscoveryEvent& e) { impl->on_discovery(e); };
    impl_->participant = std::make_unique<Participant>(o);
}

TopicProbe::~TopicProbe()
{
    auto* p = impl_->participant->native();
    if (impl_->reader) {
        impl_->reader->set_listener(nullptr);
        impl_->subscriber->delete_datareader(impl_->reader);
    }
    if (impl_->subscriber) p->delete_subscriber(impl_->subscriber);
    if (impl_->topic) p->delete_topic(impl_->topic);
    // Discovery calls on into impl_ until its participant, the first of its members to go, is gone.
}

std::vector<std::string> TopicProbe::participants() const
{
    std::vector<std::string> names;
    for (const auto& p : participants_seen()) names.push_back(p.name);
    return names;
}

std::vector<ParticipantSeen> TopicProbe::participants_seen() const
{
    std::lock_guard lock(impl_->discovery_mutex);
    const auto own = impl_->participant->native()->guid().guidPrefix;
    std::vector<ParticipantSeen> out;
    for (const auto& [prefix, p] : impl_->participants_seen) {
        if (prefix != own) out.push_back(p);
    }
    return out;
}

std::vector<TopicInfo> TopicProbe::topics() const
{
    std::lock_guard lock(impl_->discovery_mutex);
    const auto own = impl_->participant->native()->guid().guidPrefix;
    std::map<std::string, TopicInfo> by_name;
    for (const auto& [guid, e] : impl_->endpoints) {
        if (guid.guidPrefix == own) continue;
        auto& t = by_name[e.topic];
        t.name = e.topic;
        t.type_name = e.type_name;
        t.keyed = t.keyed || e.keyed;
        (e.is_writer ? t.writers : t.readers).push_back({impl_->name_of(guid.guidPrefix), e.reliable, e.transient_local});
    }
    std::vector<TopicInfo> out;
    for (auto& [name, t] : by_name) out.push_back(std::move(t));
    return out;
}

bool TopicProbe::subscribe(const std::string& topic_name, std::chrono::milliseconds timeout)
{
    Seen writer;
    {
        std::unique_lock lock(impl_->discovery_mutex);
        const auto own = impl_->participant->native()->guid().guidPrefix;
        auto find = [&] {
            for (const auto& [guid, e] : impl_->endpoints) {
                if (e.is_writer && e.topic == topic_name && guid.guidPrefix != own) {
                    writer = e;
                    return true;
                }
            }
            return false;
        };
        if (!impl_->discovered.wait_for(lock, timeout, find)) return false;
    }
    auto* p = impl_->participant->native();
    if (!register_raw_type(p, writer, IdlDecoder::lab_types()))
        throw Error("topic '" + topic_name + "': cannot register its type '" + writer.type_name + "'");
    impl_->topic = p->create_topic(topic_name, writer.type_name, dds::TOPIC_QOS_DEFAULT);
    if (!impl_->topic) throw Error("topic '" + topic_name + "': cannot create it with type '" + writer.type_name + "'");
    impl_->subscriber = p->create_subscriber(dds::SUBSCRIBER_QOS_DEFAULT);
    const dds::DataReaderQos qos = raw_reader_qos(writer.reliable, writer.transient_local);
    impl_->reader = impl_->subscriber ? impl_->subscriber->create_datareader(impl_->topic, qos, impl_.get(),
                                                                             dds::StatusMask::data_available())
                                      : nullptr;
    if (!impl_->reader) throw Error("topic '" + topic_name + "': cannot create a reader for it");
    return true;
}

std::vector<ProbeSample> TopicProbe::take(std::chrono::milliseconds timeout)
{
    std::unique_lock lock(impl_->samples_mutex);
    impl_->arrived.wait_for(lock, timeout, [&] { return !impl_->samples.empty(); });
    std::vector<ProbeSample> out(std::make_move_iterator(impl_->samples.begin()), std::make_move_iterator(impl_->samples.end()));
    impl_->samples.clear();
    return out;
}

}  // namespace cpm::rtdb
