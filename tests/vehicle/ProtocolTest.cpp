#include <cpm/vehicle/Protocol.hpp>

#include <gtest/gtest.h>

#include <algorithm>

#include <map>
#include <random>

using namespace cpm::vehicle;

namespace {

StatePacket full_state(uint32_t tick)
{
    StatePacket p;
    p.tick = tick;
    p.vehicle_id = 200;
    p.odometer_steps = -123456;
    p.speed_mm_s = -1500;
    p.imu_yaw_e4 = 31415;
    p.imu_yaw_rate_e3 = -2000;
    p.accel_forward_mm_s2 = 320;
    p.accel_left_mm_s2 = -77;
    p.accel_up_mm_s2 = 9810;
    p.battery_mv = 8123;
    p.motor_current_ma = 1500;
    p.us_front_mm = 3000;
    p.us_left_mm = 0;  // zero bytes must survive framing
    p.us_right_mm = 256;
    p.status = kStatusBadCrc | kStatusWatchdogStop;
    p.command_tick = 0xFFFFFFFF;
    return p;
}

std::vector<Packet> decode_all(FrameDecoder& sut, const std::vector<uint8_t>& bytes)
{
    std::vector<Packet> out;
    sut.feed(bytes.data(), bytes.size(), [&](const Packet& p) { out.push_back(p); });
    return out;
}

void append(std::vector<uint8_t>& to, const std::vector<uint8_t>& bytes) { to.insert(to.end(), bytes.begin(), bytes.end()); }

}  // namespace

TEST(Protocol, CrcCheckValueOf123456789Is0x29B1)
{
    const uint8_t text[] = {'1', '2', '3', '4', '5', '6', '7', '8', '9'};
    EXPECT_EQ(crc16(text, sizeof text), 0x29B1);
}

TEST(Protocol, StatePacketRoundTripsThroughAFrame)
{
    FrameDecoder sut;
    auto packets = decode_all(sut, encode_frame(full_state(42)));
    ASSERT_EQ(packets.size(), 1u);
    ASSERT_TRUE(std::holds_alternative<StatePacket>(packets[0]));
    EXPECT_EQ(std::get<StatePacket>(packets[0]), full_state(42));
    EXPECT_EQ(sut.errors().total(), 0u);
}

TEST(Protocol, CommandPacketRoundTripsThroughAFrame)
{
    CommandPacket command{0x01020304, 7, MotorMode::reverse, 999, 1234};
    FrameDecoder sut;
    auto packets = decode_all(sut, encode_frame(command));
    ASSERT_EQ(packets.size(), 1u);
    EXPECT_EQ(std::get<CommandPacket>(packets[0]), command);
}

TEST(Protocol, FieldsAreLittleEndianAfterVersionAndKind)
{
    CommandPacket command{0x04030201, 7, MotorMode::forward, 0x0302, 0x05DC};
    auto bytes = serialize(command);
    std::vector<uint8_t> expected{kProtocolVersion, 0x02, 0x01, 0x02, 0x03, 0x04, 7, 1, 0x02, 0x03, 0xDC, 0x05};
    EXPECT_EQ(bytes, expected);
}

TEST(Protocol, ParseRejectsWrongVersionKindLengthAndMotorMode)
{
    auto good = serialize(CommandPacket{1, 2, MotorMode::brake, 0, 1500});
    ASSERT_TRUE(parse(good.data(), good.size()));
    auto wrong_version = good;
    wrong_version[0] = kProtocolVersion + 1;
    EXPECT_FALSE(parse(wrong_version.data(), wrong_version.size()));
    auto wrong_kind = good;
    wrong_kind[1] = 0x7F;
    EXPECT_FALSE(parse(wrong_kind.data(), wrong_kind.size()));
    EXPECT_FALSE(parse(good.data(), good.size() - 1));
    auto wrong_mode = good;
    wrong_mode[7] = 3;
    EXPECT_FALSE(parse(wrong_mode.data(), wrong_mode.size()));
}

TEST(Protocol, CobsRoundTripsZerosAndLongRunsWithoutZeroBytes)
{
    for (size_t size : {0u, 1u, 253u, 254u, 255u, 600u}) {
        for (int pattern = 0; pattern < 3; ++pattern) {
            std::vector<uint8_t> data(size);
            for (size_t i = 0; i < size; ++i) data[i] = pattern == 0 ? 0 : pattern == 1 ? uint8_t(1 + i % 255) : uint8_t(i % 7 == 0 ? 0 : i);
            auto encoded = cobs_encode(data.data(), data.size());
            for (auto b : encoded) ASSERT_NE(b, 0) << "size " << size << " pattern " << pattern;
            auto decoded = cobs_decode(encoded.data(), encoded.size());
            ASSERT_TRUE(decoded) << "size " << size << " pattern " << pattern;
            EXPECT_EQ(*decoded, data) << "size " << size << " pattern " << pattern;
        }
    }
}

TEST(Protocol, DecoderResynchronisesAfterGarbage)
{
    std::vector<uint8_t> stream{0x13, 0x37, 0x00, 0xFF, 0x02, 0x00, 0x55};
    append(stream, encode_frame(full_state(1)));
    FrameDecoder sut;
    auto packets = decode_all(sut, stream);
    ASSERT_EQ(packets.size(), 1u);
    EXPECT_EQ(std::get<StatePacket>(packets[0]).tick, 1u);
    EXPECT_GE(sut.errors().total(), 2u);
}

TEST(Protocol, DecoderDropsACutOffFrameAndKeepsTheNextOne)
{
    auto first = encode_frame(full_state(1));
    first.resize(first.size() / 2);  // the line lost the rest, delimiter included
    std::vector<uint8_t> stream = first;
    append(stream, encode_frame(full_state(2)));
    FrameDecoder sut;
    auto packets = decode_all(sut, stream);
    ASSERT_EQ(packets.size(), 1u);
    EXPECT_EQ(std::get<StatePacket>(packets[0]).tick, 2u);
    EXPECT_EQ(sut.errors().total(), 1u);
}

TEST(Protocol, DecoderCountsABadCrcAndReturnsNothing)
{
    auto payload = serialize(full_state(5));
    payload.push_back(0x12);  // a CRC that does not match
    payload.push_back(0x34);
    auto body = cobs_encode(payload.data(), payload.size());
    std::vector<uint8_t> stream{0};
    append(stream, body);
    stream.push_back(0);
    FrameDecoder sut;
    EXPECT_TRUE(decode_all(sut, stream).empty());
    EXPECT_EQ(sut.errors().bad_crc, 1u);
    EXPECT_TRUE(sut.last_frame_bad());
}

TEST(Protocol, DecoderSkipsAnOversizeRunAndDecodesWhatFollows)
{
    std::vector<uint8_t> stream(500, 0xAB);
    append(stream, encode_frame(full_state(9)));
    FrameDecoder sut;
    auto packets = decode_all(sut, stream);
    ASSERT_EQ(packets.size(), 1u);
    EXPECT_EQ(sut.errors().oversize, 1u);
}

// 200,000 frames; about a third corrupted by a bit flip, a lost byte, an extra byte or a cut.
// No corrupted frame may come out as a packet, and every intact frame must.
TEST(Protocol, SeededRandomCorruptionNeverYieldsABadPacketAndLosesNoIntactOne)
{
    std::mt19937 rng(20261123);
    std::uniform_int_distribution<int> byte(0, 255);
    const uint32_t n = 200'000;
    std::vector<uint8_t> stream;
    std::map<uint32_t, Packet> sent;
    uint32_t intact = 0;
    for (uint32_t tick = 1; tick <= n; ++tick) {
        Packet packet = tick % 2 ? Packet(full_state(tick))
                                 : Packet(CommandPacket{tick, uint8_t(tick), MotorMode(tick % 3), uint16_t(tick % 1001), uint16_t(1000 + tick % 1001)});
        sent[tick] = packet;
        auto frame = encode_frame(packet);
        switch (rng() % 6) {
        case 0: frame[1 + rng() % (frame.size() - 2)] ^= uint8_t(1u << (rng() % 8)); break;
        case 1: frame.erase(frame.begin() + 1 + long(rng() % (frame.size() - 2))); break;
        case 2: frame.insert(frame.begin() + 1 + long(rng() % (frame.size() - 2)), uint8_t(byte(rng))); break;
        case 3: frame.resize(1 + rng() % (frame.size() - 2)); break;
        default: ++intact; break;
        }
        append(stream, frame);
    }
    FrameDecoder sut;
    uint64_t accepted = 0, mismatched = 0;
    size_t pos = 0;
    while (pos < stream.size()) {
        size_t chunk = std::min<size_t>(1 + rng() % 97, stream.size() - pos);
        sut.feed(stream.data() + pos, chunk, [&](const Packet& p) {
            ++accepted;
            uint32_t tick = std::visit([](const auto& q) { return q.tick; }, p);
            auto it = sent.find(tick);
            if (it == sent.end() || !(serialize(it->second) == serialize(p))) ++mismatched;
        });
        pos += chunk;
    }
    EXPECT_EQ(mismatched, 0u);
    EXPECT_GE(accepted, intact);
    EXPECT_GT(sut.errors().bad_crc + sut.errors().bad_cobs + sut.errors().too_short, n / 4);
    std::printf("frames %u, intact %u, accepted %llu, errors: oversize %llu bad_cobs %llu too_short %llu bad_crc %llu bad_packet %llu\n",
                n, intact, (unsigned long long)accepted, (unsigned long long)sut.errors().oversize,
                (unsigned long long)sut.errors().bad_cobs, (unsigned long long)sut.errors().too_short,
                (unsigned long long)sut.errors().bad_crc, (unsigned long long)sut.errors().bad_packet);
}

TEST(Protocol, TheFirmwaresCSourceLaysOutACommandByteForByteAndDecodesItsOwnFrame)
{
    // The C code the AVR firmware runs (firmware/protocol/cpm_serial.c), called directly: the
    // bytes written by hand from the protocol's table (README), little-endian after version 2
    // and kind 2.
    const cpm_command_packet c{0x01020304u, 7, CPM_MOTOR_FORWARD, 500, 1600};
    uint8_t payload[CPM_SERIAL_COMMAND_SIZE];
    ASSERT_EQ(cpm_command_pack(&c, payload), size_t(CPM_SERIAL_COMMAND_SIZE));
    const std::vector<uint8_t> by_hand{0x02, 0x02, 0x04, 0x03, 0x02, 0x01, 0x07, 0x01, 0xF4, 0x01, 0x40, 0x06};
    EXPECT_EQ(std::vector<uint8_t>(payload, payload + sizeof payload), by_hand);

    uint8_t frame[CPM_SERIAL_MAX_WIRE + 4];
    const size_t n = cpm_frame_encode(payload, sizeof payload, frame);
    EXPECT_EQ(frame[0], 0);
    EXPECT_EQ(frame[n - 1], 0);
    EXPECT_EQ(std::count(frame + 1, frame + n - 1, 0), 0) << "COBS leaves no zero inside a frame";
    // The same bytes as the host's C++ face makes, and the C decoder hands back the payload.
    EXPECT_EQ(std::vector<uint8_t>(frame, frame + n),
              cpm::vehicle::encode_frame(cpm::vehicle::CommandPacket{0x01020304u, 7, cpm::vehicle::MotorMode::forward, 500, 1600}));
    cpm_decoder d;
    cpm_decoder_init(&d);
    int last = CPM_DECODE_NONE;
    for (size_t i = 0; i < n; ++i) last = cpm_decoder_push(&d, frame[i]);
    ASSERT_EQ(last, CPM_DECODE_PAYLOAD);
    cpm_command_packet back{};
    ASSERT_EQ(cpm_command_unpack(d.payload, d.payload_size, &back), 0);
    EXPECT_EQ(back.tick, c.tick);
    EXPECT_EQ(back.servo_us, 1600);
    // One bit off in the body: the C decoder names the bad CRC, the C++ face counts it.
    frame[5] ^= 0x01;
    for (size_t i = 0; i < n; ++i) last = cpm_decoder_push(&d, frame[i]);
    EXPECT_EQ(last, CPM_DECODE_BAD_CRC);
}
