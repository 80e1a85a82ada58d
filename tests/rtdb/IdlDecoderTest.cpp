// cpm::rtdb::IdlDecoder: the lab's IDL read at run time decodes samples, says which types have
// a Header, and gives each instance's key as text and as DDS hashes it (equal to the writer's).
#include <cpm/Error.hpp>
#include <cpm/rtdb/IdlDecoder.hpp>

#include <ParameterPubSubTypes.h>
#include <VehicleStatePubSubTypes.h>

#include "serialized.hpp"

#include <fastrtps/utils/md5.h>

#include <gtest/gtest.h>

namespace {

using cpm::rtdb::IdlDecoder;
using Sources = std::map<std::string, std::string>;

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

TEST(IdlDecoder, ReadsEveryKindOfMemberTheLabsIdlUses)
{
    const IdlDecoder sut(Sources{{"kinds.idl", "#include \"Other.idl\"\n"
                                        "module lab {\n"
                                        "  enum Light { red, /* amber, */ green };  // the second is green\n"
                                        "  struct Inner { double x; double y; };\n"
                                        "  struct Thing;  // a forward declaration\n"
                                        "  @final struct Thing {\n"
                                        "    @key unsigned short id;\n"
                                        "    unsigned   long\n long big;\n"
                                        "    long long small; unsigned long mid; short tiny; long plain;\n"
                                        "    @key(true) string name;\n"
                                        "    @key(false) octet not_a_key;\n"
                                        "    sequence< double , 3 > few;\n"
                                        "    sequence<Inner> many;\n"
                                        "    Inner corners[ 2 ];\n"
                                        "    Light light;\n"
                                        "  };\n"
                                        "};\n"}});
    ASSERT_TRUE(sut.knows("Thing"));
    EXPECT_FALSE(sut.knows("Light")) << "an enum is no struct";
    EXPECT_EQ(sut.key_members("Thing"), (std::vector<std::string>{"id", "name"}));
    const std::vector<std::pair<std::string, std::string>> types = {
        {"id", "unsigned short"}, {"big", "unsigned long long"}, {"small", "long long"}, {"mid", "unsigned long"},
        {"tiny", "short"},        {"plain", "long"},             {"name", "string"},     {"not_a_key", "octet"},
        {"few", "sequence< double , 3 >"}, {"many", "sequence<Inner>"}, {"corners", "Inner"}, {"light", "Light"}};
    for (const auto& [member, type] : types) EXPECT_EQ(sut.member_type("Thing", member), type) << member;
    EXPECT_EQ(sut.field_paths("Thing"), (std::vector<std::string>{"id", "big", "small", "mid", "tiny", "plain", "name", "not_a_key",
                                                                  "few", "many", "corners", "light"}));

    const nlohmann::json sample = {{"id", 7},     {"big", 18446744073709551615ull}, {"small", -5}, {"mid", 4000000000u},
                                   {"tiny", -2},  {"plain", -70000},                {"name", "seven"}, {"not_a_key", 1},
                                   {"few", {0.5, 1.5}}, {"many", {{{"x", 1.0}, {"y", 2.0}}}},
                                   {"corners", {{{"x", 3.0}, {"y", 4.0}}, {{"x", 5.0}, {"y", 6.0}}}}, {"light", "green"}};
    const auto bytes = sut.encode("Thing", sample);
    EXPECT_EQ(sut.decode("Thing", bytes), sample);
    EXPECT_FALSE(sut.decode("Thing", std::vector<uint8_t>(bytes.begin(), bytes.end() - 1))) << "a payload that ends early";
    EXPECT_THROW((void)sut.encode("Thing", {{"few", {1.0, 2.0, 3.0, 4.0}}}), cpm::Error) << "past the sequence's bound";
}

TEST(IdlDecoder, AnIdlItCannotReadIsACpmErrorNamingFileLineAndWhat)
{
    const std::vector<std::pair<std::string, std::string>> cases = {
        {"struct A { long x; };\n/* never closed\n", "bad.idl:2: a /* comment that never ends"},
        {"\nstruct A {\n long x;\n", "bad.idl:2: struct A: no closing }"},
        {"enum E { a, b }\n", "bad.idl:1: enum E: expected ; after }"},
        {"struct A {\n long x;\n long y\n};\n", "bad.idl:3: struct A: member 'long y' has no ;"},
        {"struct A {\n long x y;\n};\n", "bad.idl:2: struct A: cannot read member 'long x y'"},
        {"struct A {\n @key long;\n};\n", "bad.idl:2: struct A: cannot read member 'long'"},
        {"struct A {\n sequence<long x;\n};\n", "bad.idl:2: struct A: cannot read member 'sequence<long x'"},
        {"struct A {\n sequence<long, many> x;\n};\n",
         "bad.idl:2: struct A: cannot read member 'sequence<long, many> x': expected sequence<TYPE> or sequence<TYPE, BOUND>"},
        {"struct A {\n long x[n];\n};\n", "bad.idl:2: struct A: cannot read member 'long x[n]': expected [N]"},
        {"struct A {\n long x[3;\n};\n", "bad.idl:2: struct A: cannot read member 'long x[3': expected [N]"},
        {"struct A {\n long x[0];\n};\n", "bad.idl:2: struct A: cannot read member 'long x[0]': an array of 1..1000000 items"},
        {"struct A {\n long x[1000001];\n};\n", "bad.idl:2: struct A: cannot read member 'long x[1000001]': an array of 1..1000000 items"},
    };
    for (const auto& [text, message] : cases) {
        try {
            const IdlDecoder sut(Sources{{"bad.idl", text}});
            ADD_FAILURE() << "read: " << text;
        } catch (const cpm::Error& e) {
            EXPECT_EQ(std::string(e.what()), message) << text;
        }
    }
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
