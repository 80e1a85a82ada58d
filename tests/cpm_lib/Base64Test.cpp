// cpm::base64_encode / base64_decode against RFC 4648's test vectors (section 10), and back.
#include <cpm/base64.hpp>

#include <gtest/gtest.h>

namespace {

std::vector<uint8_t> bytes(const std::string& s) { return {s.begin(), s.end()}; }

}  // namespace

TEST(Base64, EncodesTheRfcVectorsAndDecodesThemBack)
{
    const std::vector<std::pair<std::string, std::string>> vectors{
        {"", ""}, {"f", "Zg=="}, {"fo", "Zm8="}, {"foo", "Zm9v"}, {"foob", "Zm9vYg=="}, {"fooba", "Zm9vYmE="}, {"foobar", "Zm9vYmFy"}};
    for (const auto& [plain, coded] : vectors) {
        EXPECT_EQ(cpm::base64_encode(bytes(plain)), coded) << plain;
        EXPECT_EQ(cpm::base64_decode(coded), bytes(plain)) << coded;
    }
    const std::vector<uint8_t> all_values = [] {
        std::vector<uint8_t> v;
        for (int i = 0; i < 256; ++i) v.push_back(uint8_t(i));
        return v;
    }();
    EXPECT_EQ(cpm::base64_decode(cpm::base64_encode(all_values)), all_values);
    EXPECT_EQ(cpm::base64_decode("Zm9v\nYmFy"), bytes("foobar")) << "line breaks are passed over";
}
