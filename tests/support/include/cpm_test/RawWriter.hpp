#pragma once
// A writer that puts any bytes on the wire as a sample of a named type: for tests that send what
// no well-behaved cpm writer would (a wrong encapsulation, a cut-off sample) to a real reader.
#include <cpm/Participant.hpp>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace cpm_test {

class RawWriter
{
public:
    /// A best-effort (or reliable) keyed writer of `type_name` on `topic`; the key hash is the
    /// byte at `key_offset` of each sample (a lab type's vehicle_id sits right after the 4-byte
    /// encapsulation and the 16-byte Header: offset 20).
    RawWriter(cpm::Participant& participant, const std::string& topic, const std::string& type_name, bool reliable = false,
              size_t key_offset = 20);
    ~RawWriter();
    RawWriter(const RawWriter&) = delete;
    RawWriter& operator=(const RawWriter&) = delete;

    /// Writes the bytes as they are (encapsulation header included).
    bool write(const std::vector<uint8_t>& bytes);
    /// The number of readers matched.
    int matched() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm_test
