// The serial link's byte stream (vehicle_bridge ← car, firmware ← bridge): any bytes through the
// frame decoder. Every packet it hands out must survive a round trip through the encoder, and COBS
// must decode what it encodes.
#include "../Fuzz.hpp"

#include <cpm/vehicle/Protocol.hpp>

CPM_FUZZ_TARGET(serial_frame)
{
    using namespace cpm::vehicle;
    FrameDecoder decoder;
    size_t packets = 0;
    decoder.feed(data, size, [&](const Packet& p) {
        ++packets;
        const auto frame = encode_frame(p);
        FrameDecoder again;
        std::optional<Packet> back;
        again.feed(frame.data(), frame.size(), [&](const Packet& q) { back = q; });
        cpm::fuzz::expect(back.has_value() && *back == p, "a decoded packet does not survive encode_frame → decode");
    });

    const auto cobs = cobs_encode(data, size);
    for (uint8_t b : cobs) cpm::fuzz::expect(b != 0, "COBS output holds a zero byte");
    const auto decoded = cobs_decode(cobs.data(), cobs.size());
    cpm::fuzz::expect(decoded && *decoded == std::vector<uint8_t>(data, data + size), "cobs_decode(cobs_encode(x)) != x");
    (void)cobs_decode(data, size);
    if (auto p = parse(data, size)) cpm::fuzz::expect(serialize(*p) == std::vector<uint8_t>(data, data + size), "serialize(parse(x)) != x");
    return 0;
}
