// cpm::rtdb::IdlDecoder: the lab's IDL read at run time decodes samples, says which types have
// a Header, and gives each instance's key as text and as DDS hashes it (equal to the writer's).
#include <cpm/rtdb/IdlDecoder.hpp>

#include <ParameterPubSubTypes.h>
#include <VehicleStatePubSubTypes.h>

#include "serialized.hpp"

#include <fastrtps/utils/md5.h>

#include <gtest/gtest.h>

namespace {

using cpm::rtdb::IdlDecoder;

template <class PubSub, class T>
eprosima::fastrtps::rtps::InstanceHandle_t writers_key_hash(T sample)
{
    PubSub type;
    eprosima::fastrtps::rtps::InstanceHandle_t handle;
    EXPECT_TRUE(type.getKey(&sample, &handle, false));
    return handle;
}

std::array<uint8_t, 16> hash_of(const IdlDecoder::KeyBytes& key)
{
    std::array<uint8_t, 16> out{};
    if (key.md5) {
        ::MD5 md5;
        md5.init();
        md5.update(key.bytes.data(), static_cast<unsigned int>(key.bytes.size()));
        md5.finalize();
        std::copy(md5.digest, md5.digest + 16, out.begin());
    } else {
        std::copy(key.bytes.begin(), key.bytes.begin() + std::min<size_t>(16, key.bytes.size()), out.begin());
    }
    return out;
}

std::array<uint8_t, 16> value_of(const eprosima::fastrtps::rtps::InstanceHandle_t& h)
{
    std::array<uint8_t, 16> out{};
    for (size_t i = 0; i < 16; ++i) out[i] = h.value[i];
    return out;
}

TEST(IdlDecoder, AStringKeyIsGivenAsTextAndHashedAsTheWriterHashesIt)
{
    const IdlDecoder* sut = IdlDecoder::lab_types();
    ASSERT_NE(sut, nullptr);
    Parameter p;
    p.name("max_speed");
    p.type(ParameterType_Double);
    p.values_double({0.7});
    const auto bytes = serialized<ParameterPubSubType>(p);
    EXPECT_EQ(sut->key_members("Parameter"), std::vector<std::string>{"name"});
    EXPECT_EQ(sut->key_text("Parameter", bytes.data(), bytes.size()), "max_speed");
    auto key = sut->key_bytes("Parameter", bytes.data(), bytes.size());
    ASSERT_TRUE(key);
    EXPECT_TRUE(key->md5);
    EXPECT_EQ(hash_of(*key), value_of(writers_key_hash<ParameterPubSubType>(p)));
    EXPECT_FALSE(sut->has_header("Parameter"));
    EXPECT_FALSE(sut->has_header("Log"));
}

TEST(IdlDecoder, AVehicleIdKeyIsItsNumberAndTheHashIsTheOctetPadded)
{
    const IdlDecoder* sut = IdlDecoder::lab_types();
    ASSERT_NE(sut, nullptr);
    VehicleState s;
    s.vehicle_id(42);
    s.pose().x(1.5);
    const auto bytes = serialized<VehicleStatePubSubType>(s);
    EXPECT_EQ(sut->key_text("VehicleState", bytes.data(), bytes.size()), "42");
    auto key = sut->key_bytes("VehicleState", bytes.data(), bytes.size());
    ASSERT_TRUE(key);
    EXPECT_FALSE(key->md5);
    EXPECT_EQ(hash_of(*key), value_of(writers_key_hash<VehicleStatePubSubType>(s)));
    EXPECT_TRUE(sut->has_header("VehicleState"));
    EXPECT_EQ((*sut->decode("VehicleState", bytes))["pose"]["x"], 1.5);
}

TEST(IdlDecoder, UnknownTypesAndBytesThatDoNotDecodeGiveNothing)
{
    const IdlDecoder* sut = IdlDecoder::lab_types();
    ASSERT_NE(sut, nullptr);
    const std::vector<uint8_t> short_bytes{0, 1, 0, 0, 7};
    EXPECT_FALSE(sut->key_text("NoSuchType", short_bytes.data(), short_bytes.size()));
    EXPECT_FALSE(sut->key_text("Parameter", short_bytes.data(), short_bytes.size()));
    EXPECT_FALSE(sut->key_bytes("Log", short_bytes.data(), short_bytes.size()));  // unkeyed
    EXPECT_FALSE(sut->has_header("NoSuchType"));
}

}  // namespace
