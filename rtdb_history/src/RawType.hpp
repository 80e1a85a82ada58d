#pragma once
// A DDS type that keeps the serialized payload as it came off the wire, for topics of types
// cpm_history was never compiled with. The instance key of a keyed type comes from the
// writer's key hash when it sends one. Otherwise, for a type whose IDL the service knows, it
// is computed from the @key members exactly as DDS does (XTypes 1.3 §7.6.8: big-endian CDR,
// MD5 when the key may exceed 16 bytes), so it equals the writer's own; for an unknown type
// it is the octet right after a 16-byte Header (a lab type's vehicle_id).
#include <cpm/Discovery.hpp>
#include <cpm/rtdb/IdlDecoder.hpp>

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/qos/DataReaderQos.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <fastdds/rtps/common/Guid.h>
#include <fastdds/dds/topic/TopicDataType.hpp>
#include <fastrtps/utils/md5.h>

#include <cstring>
#include <sstream>
#include <string>
#include <vector>

namespace cpm::rtdb {

struct RawSample
{
    std::vector<uint8_t> bytes;  ///< encapsulation header included
};

/// A raw reader's QoS, compatible with a writer that offers this reliability and durability
/// (as reliable and as durable as it), keeping everything until taken.
inline eprosima::fastdds::dds::DataReaderQos raw_reader_qos(bool reliable, bool transient_local)
{
    namespace dds = eprosima::fastdds::dds;
    dds::DataReaderQos qos = dds::DATAREADER_QOS_DEFAULT;
    qos.reliability().kind = reliable ? dds::RELIABLE_RELIABILITY_QOS : dds::BEST_EFFORT_RELIABILITY_QOS;
    qos.durability().kind = transient_local ? dds::TRANSIENT_LOCAL_DURABILITY_QOS : dds::VOLATILE_DURABILITY_QOS;
    qos.history().kind = dds::KEEP_ALL_HISTORY_QOS;
    qos.resource_limits().max_samples = 0;
    qos.resource_limits().max_instances = 0;
    qos.resource_limits().max_samples_per_instance = 0;
    // Not DYNAMIC_REUSABLE: Fast DDS 2.9's reader then refuses a dispose (its payload is
    // empty) and never acknowledges it; the disposed object stayed alive until its writer left.
    qos.endpoint().history_memory_policy = eprosima::fastrtps::rtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;
    qos.data_sharing().off();
    return qos;
}

class RawType : public eprosima::fastdds::dds::TopicDataType
{
public:
    RawType(const std::string& type_name, bool keyed, const IdlDecoder* types)
        : type_name_(type_name), types_(types && types->knows(type_name) ? types : nullptr)
    {
        setName(type_name.c_str());
        m_typeSize = 4096;  // the initial buffer; larger samples get larger buffers
        m_isGetKeyDefined = keyed;
    }
    bool serialize(void* data, eprosima::fastrtps::rtps::SerializedPayload_t* payload) override
    {
        const auto& b = static_cast<RawSample*>(data)->bytes;
        if (payload->max_size < b.size()) payload->reserve(static_cast<uint32_t>(b.size()));
        std::memcpy(payload->data, b.data(), b.size());
        payload->length = static_cast<uint32_t>(b.size());
        return true;
    }
    bool deserialize(eprosima::fastrtps::rtps::SerializedPayload_t* payload, void* data) override
    {
        static_cast<RawSample*>(data)->bytes.assign(payload->data, payload->data + payload->length);
        return true;
    }
    std::function<uint32_t()> getSerializedSizeProvider(void* data) override
    {
        return [data] { return static_cast<uint32_t>(static_cast<RawSample*>(data)->bytes.size()); };
    }
    void* createData() override { return new RawSample; }
    void deleteData(void* data) override { delete static_cast<RawSample*>(data); }
    bool getKey(void* data, eprosima::fastrtps::rtps::InstanceHandle_t* handle, bool) override
    {
        const auto& b = static_cast<RawSample*>(data)->bytes;
        for (size_t i = 0; i < 16; ++i) handle->value[i] = 0;
        if (types_) {
            const auto key = types_->key_bytes(type_name_, b.data(), b.size());
            if (!key) return false;
            if (key->md5) {
                ::MD5 md5;
                md5.init();
                md5.update(key->bytes.data(), static_cast<unsigned int>(key->bytes.size()));
                md5.finalize();
                for (size_t i = 0; i < 16; ++i) handle->value[i] = md5.digest[i];
            } else {
                for (size_t i = 0; i < 16 && i < key->bytes.size(); ++i) handle->value[i] = key->bytes[i];
            }
            return true;
        }
        if (b.size() > 4 + 16) handle->value[0] = b[4 + 16];
        return true;
    }

private:
    std::string type_name_;
    const IdlDecoder* types_;
};

/// What a discovered endpoint says of its topic, as the raw readers need it.
struct RawEndpoint
{
    std::string topic, type_name;
    bool keyed = false, reliable = false, transient_local = false;
};

/// A discovered writer or reader as a raw endpoint.
inline RawEndpoint raw_endpoint(const DiscoveryEvent& e) { return {e.topic, e.type_name, e.keyed, e.reliable, e.transient_local}; }

/// A discovery event's GUID as Fast DDS's.
inline eprosima::fastrtps::rtps::GUID_t fast_dds_guid(const DiscoveryEvent& e)
{
    eprosima::fastrtps::rtps::GUID_t g;
    std::memcpy(g.guidPrefix.value, e.guid.data(), 12);
    std::memcpy(g.entityId.value, e.guid.data() + 12, 4);
    return g;
}

/// Registers the raw type under `type_name` in the participant unless a type of that name is
/// there already; false when DDS refuses.
inline bool register_raw_type(eprosima::fastdds::dds::DomainParticipant* participant, const RawEndpoint& e, const IdlDecoder* types)
{
    if (!participant->find_type(e.type_name).empty()) return true;
    eprosima::fastdds::dds::TypeSupport type(new RawType(e.type_name, e.keyed, types));
    type->auto_fill_type_information(false);
    type->auto_fill_type_object(false);
    return type.register_type(participant) == ReturnCode_t::RETCODE_OK;
}

/// The writer's source timestamp of a sample, in ns.
inline uint64_t source_time_ns(const eprosima::fastdds::dds::SampleInfo& info)
{
    return uint64_t(info.source_timestamp.seconds()) * 1'000'000'000ull + info.source_timestamp.nanosec();
}

/// A participant's GUID prefix as Fast DDS prints it.
inline std::string guid_prefix_text(const eprosima::fastrtps::rtps::GuidPrefix_t& p)
{
    std::ostringstream s;
    s << p;
    return s.str();
}

}  // namespace cpm::rtdb
