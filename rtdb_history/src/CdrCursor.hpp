#pragma once
// Reading a serialized sample for IdlDecoder::decode.
#include <cpm/Error.hpp>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>

namespace cpm::rtdb {

/// Reads plain CDR: each primitive aligned to its size from the start of the data (after the
/// 4-byte encapsulation header), in the encapsulation's byte order. Throws when the payload
/// ends before what is read, a cpm::Error (IdlDecoder::decode turns that into "does not decode").
class CdrCursor
{
public:
    CdrCursor(const uint8_t* data, size_t size) : b_(data), size_(size), little_(size >= 2 && (data[1] & 1)) {}
    template <typename T>
    T get()
    {
        align(sizeof(T));
        need(sizeof(T));
        uint8_t raw[sizeof(T)];
        for (size_t i = 0; i < sizeof(T); ++i) raw[i] = b_[at_ + (little_ ? i : sizeof(T) - 1 - i)];
        at_ += sizeof(T);
        T v;
        std::memcpy(&v, raw, sizeof(T));
        return v;
    }
    std::string string()
    {
        const uint32_t n = get<uint32_t>();
        need(n);
        std::string s(reinterpret_cast<const char*>(b_ + at_), n ? n - 1 : 0);
        at_ += n;
        return s;
    }
    /// Whether there is an encapsulation header to read after.
    bool ok() const { return size_ >= 4; }

private:
    void align(size_t n) { at_ = 4 + (at_ - 4 + n - 1) / n * n; }
    void need(size_t n)
    {
        if (n > size_ || at_ > size_ - n) throw Error("payload ends early");
    }
    const uint8_t* b_;
    size_t size_;
    bool little_;
    size_t at_ = 4;
};

}  // namespace cpm::rtdb
