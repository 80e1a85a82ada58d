#pragma once
// A sample as a writer puts it on the wire (CDR, encapsulation included), for tests that feed a
// store or a decoder without DDS.
#include <fastrtps/rtps/common/SerializedPayload.h>

#include <gtest/gtest.h>

#include <cstdint>
#include <vector>

template <class PubSub, class T>
std::vector<uint8_t> serialized(T sample)
{
    PubSub type;
    eprosima::fastrtps::rtps::SerializedPayload_t payload(type.m_typeSize);
    EXPECT_TRUE(type.serialize(&sample, &payload));
    return {payload.data, payload.data + payload.length};
}
