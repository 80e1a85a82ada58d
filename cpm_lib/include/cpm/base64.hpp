#pragma once
// RFC 4648 base64, as cpm's JSON carries bytes (a payload of a type cpm does not know).
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace cpm {

/// The bytes as base64, with padding.
std::string base64_encode(const std::vector<uint8_t>& bytes);
/// The bytes of base64 text; characters outside the alphabet ('=', line breaks) are passed over.
std::vector<uint8_t> base64_decode(std::string_view text);

}  // namespace cpm
