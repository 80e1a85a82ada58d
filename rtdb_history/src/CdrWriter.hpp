#pragma once
// Writing a sample for IdlDecoder::encode: the reverse of CdrCursor.
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

namespace cpm::rtdb {

/// Writes XCDR1 little endian after a 4-byte encapsulation header; alignment counts from after it.
class CdrWriter
{
public:
    CdrWriter() : b_{0x00, 0x01, 0x00, 0x00} {}
    template <typename T>
    void put(T v)
    {
        while ((b_.size() - 4) % sizeof(T)) b_.push_back(0);
        uint8_t raw[sizeof(T)];
        std::memcpy(raw, &v, sizeof(T));  // little endian host (x86, ARM)
        b_.insert(b_.end(), raw, raw + sizeof(T));
    }
    void string(const std::string& s)
    {
        put<uint32_t>(uint32_t(s.size() + 1));
        b_.insert(b_.end(), s.begin(), s.end());
        b_.push_back(0);
    }
    std::vector<uint8_t> bytes() { return std::move(b_); }

private:
    std::vector<uint8_t> b_;
};

}  // namespace cpm::rtdb
