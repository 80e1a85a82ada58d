#pragma once
// A DDS type that keeps the serialized payload as it came off the wire, for topics of types
// cpm_history was never compiled with. The instance key of a keyed type comes from the
// writer's key hash when it sends one; otherwise it is taken as a lab type's (the octet
// vehicle_id right after the 16-byte Header).
#include <fastdds/dds/topic/TopicDataType.hpp>

#include <cstring>
#include <vector>

namespace cpm::rtdb {

struct RawSample
{
    std::vector<uint8_t> bytes;  ///< encapsulation header included
};

class RawType : public eprosima::fastdds::dds::TopicDataType
{
public:
    RawType(const std::string& type_name, bool keyed)
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
        if (b.size() > 4 + 16) handle->value[0] = b[4 + 16];
        return true;
    }
};

}  // namespace cpm::rtdb
