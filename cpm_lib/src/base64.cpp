#include <cpm/base64.hpp>

namespace cpm {

namespace {
constexpr std::string_view kAlphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
}

std::string base64_encode(const std::vector<uint8_t>& b)
{
    std::string out;
    out.reserve((b.size() + 2) / 3 * 4);
    for (size_t i = 0; i < b.size(); i += 3) {
        const uint32_t v = uint32_t(b[i]) << 16 | (i + 1 < b.size() ? uint32_t(b[i + 1]) << 8 : 0) | (i + 2 < b.size() ? b[i + 2] : 0);
        out += kAlphabet[v >> 18 & 63];
        out += kAlphabet[v >> 12 & 63];
        out += i + 1 < b.size() ? kAlphabet[v >> 6 & 63] : '=';
        out += i + 2 < b.size() ? kAlphabet[v & 63] : '=';
    }
    return out;
}

std::vector<uint8_t> base64_decode(std::string_view text)
{
    std::vector<uint8_t> out;
    uint32_t value = 0;
    int bits = 0;
    for (char c : text) {
        const auto p = kAlphabet.find(c);
        if (p == std::string_view::npos) continue;
        value = (value << 6) | uint32_t(p);
        bits += 6;
        if (bits >= 8) {
            bits -= 8;
            out.push_back(uint8_t((value >> bits) & 0xff));
        }
    }
    return out;
}

}  // namespace cpm
