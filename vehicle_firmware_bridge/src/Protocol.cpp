#include <cpm/vehicle/Protocol.hpp>

#include <type_traits>

namespace cpm::vehicle {
namespace {

enum PacketKind : uint8_t { kKindState = 0x01, kKindCommand = 0x02 };

constexpr size_t kStatePayloadSize = 2 + 4 + 1 + 4 + 2 * 6 + 2 * 5 + 1 + 4;
constexpr size_t kCommandPayloadSize = 2 + 4 + 1 + 1 + 2 + 2;

/// Appends integers little-endian, one byte at a time (independent of the host's order).
class ByteWriter
{
public:
    explicit ByteWriter(uint8_t kind) { bytes_.push_back(kProtocolVersion); bytes_.push_back(kind); }
    template <class T>
    ByteWriter& put(T value)
    {
        using U = std::make_unsigned_t<T>;
        auto u = static_cast<U>(value);
        for (size_t i = 0; i < sizeof(T); ++i) bytes_.push_back(static_cast<uint8_t>(u >> (8 * i)));
        return *this;
    }
    std::vector<uint8_t> take() { return std::move(bytes_); }

private:
    std::vector<uint8_t> bytes_;
};

/// Reads what ByteWriter wrote; the caller has checked the length.
class ByteReader
{
public:
    explicit ByteReader(const uint8_t* data) : data_(data) {}
    template <class T>
    T get()
    {
        using U = std::make_unsigned_t<T>;
        U u = 0;
        for (size_t i = 0; i < sizeof(T); ++i) u = static_cast<U>(u | static_cast<U>(U(data_[pos_ + i]) << (8 * i)));
        pos_ += sizeof(T);
        return static_cast<T>(u);
    }

private:
    const uint8_t* data_;
    size_t pos_ = 0;
};

std::vector<uint8_t> serialize_state(const StatePacket& p)
{
    ByteWriter w(kKindState);
    w.put(p.tick).put(p.vehicle_id).put(p.odometer_steps).put(p.speed_mm_s).put(p.imu_yaw_e4).put(p.imu_yaw_rate_e3);
    w.put(p.accel_forward_mm_s2).put(p.accel_left_mm_s2).put(p.accel_up_mm_s2);
    w.put(p.battery_mv).put(p.motor_current_ma).put(p.us_front_mm).put(p.us_left_mm).put(p.us_right_mm);
    w.put(p.status).put(p.command_tick);
    return w.take();
}

std::vector<uint8_t> serialize_command(const CommandPacket& p)
{
    ByteWriter w(kKindCommand);
    w.put(p.tick).put(p.vehicle_id).put(static_cast<uint8_t>(p.motor_mode)).put(p.motor_pwm).put(p.servo_us);
    return w.take();
}

StatePacket parse_state(ByteReader r)
{
    StatePacket p;
    p.tick = r.get<uint32_t>();
    p.vehicle_id = r.get<uint8_t>();
    p.odometer_steps = r.get<int32_t>();
    p.speed_mm_s = r.get<int16_t>();
    p.imu_yaw_e4 = r.get<int16_t>();
    p.imu_yaw_rate_e3 = r.get<int16_t>();
    p.accel_forward_mm_s2 = r.get<int16_t>();
    p.accel_left_mm_s2 = r.get<int16_t>();
    p.accel_up_mm_s2 = r.get<int16_t>();
    p.battery_mv = r.get<uint16_t>();
    p.motor_current_ma = r.get<uint16_t>();
    p.us_front_mm = r.get<uint16_t>();
    p.us_left_mm = r.get<uint16_t>();
    p.us_right_mm = r.get<uint16_t>();
    p.status = r.get<uint8_t>();
    p.command_tick = r.get<uint32_t>();
    return p;
}

std::optional<CommandPacket> parse_command(ByteReader r)
{
    CommandPacket p;
    p.tick = r.get<uint32_t>();
    p.vehicle_id = r.get<uint8_t>();
    auto mode = r.get<uint8_t>();
    if (mode > static_cast<uint8_t>(MotorMode::reverse)) return std::nullopt;
    p.motor_mode = static_cast<MotorMode>(mode);
    p.motor_pwm = r.get<uint16_t>();
    p.servo_us = r.get<uint16_t>();
    return p;
}

}  // namespace

bool StatePacket::operator==(const StatePacket& o) const { return serialize_state(*this) == serialize_state(o); }
bool CommandPacket::operator==(const CommandPacket& o) const { return serialize_command(*this) == serialize_command(o); }

uint16_t crc16(const uint8_t* data, size_t size)
{
    uint16_t crc = 0xFFFF;
    for (size_t i = 0; i < size; ++i) {
        crc = static_cast<uint16_t>(crc ^ (uint16_t(data[i]) << 8));
        for (int bit = 0; bit < 8; ++bit) {
            crc = (crc & 0x8000) ? static_cast<uint16_t>((crc << 1) ^ 0x1021) : static_cast<uint16_t>(crc << 1);
        }
    }
    return crc;
}

std::vector<uint8_t> cobs_encode(const uint8_t* data, size_t size)
{
    std::vector<uint8_t> out;
    out.reserve(size + size / 254 + 2);
    size_t code_pos = 0;
    out.push_back(0);
    uint8_t code = 1;
    auto close_block = [&] {
        out[code_pos] = code;
        code_pos = out.size();
        out.push_back(0);
        code = 1;
    };
    for (size_t i = 0; i < size; ++i) {
        if (data[i] == 0) {
            close_block();
            continue;
        }
        out.push_back(data[i]);
        if (++code == 0xFF) close_block();
    }
    out[code_pos] = code;
    return out;
}

std::optional<std::vector<uint8_t>> cobs_decode(const uint8_t* data, size_t size)
{
    std::vector<uint8_t> out;
    out.reserve(size);
    size_t i = 0;
    while (i < size) {
        uint8_t code = data[i];
        if (code == 0 || i + code > size) return std::nullopt;
        for (size_t k = 1; k < code; ++k) {
            if (data[i + k] == 0) return std::nullopt;
            out.push_back(data[i + k]);
        }
        i += code;
        // A block shorter than 254 bytes stood for a zero, except at the very end.
        if (code != 0xFF && i < size) out.push_back(0);
    }
    return out;
}

std::vector<uint8_t> serialize(const Packet& packet)
{
    if (auto* state = std::get_if<StatePacket>(&packet)) return serialize_state(*state);
    return serialize_command(std::get<CommandPacket>(packet));
}

std::optional<Packet> parse(const uint8_t* data, size_t size)
{
    if (size < 2 || data[0] != kProtocolVersion) return std::nullopt;
    ByteReader fields(data + 2);
    if (data[1] == kKindState && size == kStatePayloadSize) return Packet(parse_state(fields));
    if (data[1] == kKindCommand && size == kCommandPayloadSize) {
        if (auto command = parse_command(fields)) return Packet(*command);
    }
    return std::nullopt;
}

std::vector<uint8_t> encode_frame(const Packet& packet)
{
    auto bytes = serialize(packet);
    uint16_t crc = crc16(bytes.data(), bytes.size());
    bytes.push_back(static_cast<uint8_t>(crc & 0xFF));
    bytes.push_back(static_cast<uint8_t>(crc >> 8));
    auto body = cobs_encode(bytes.data(), bytes.size());
    std::vector<uint8_t> frame;
    frame.reserve(body.size() + 2);
    frame.push_back(0);
    frame.insert(frame.end(), body.begin(), body.end());
    frame.push_back(0);
    return frame;
}

std::optional<Packet> FrameDecoder::push(uint8_t byte)
{
    if (byte != 0) {
        if (discarding_) return std::nullopt;
        if (frame_.size() == kMaxFrame) {
            ++errors_.oversize;
            last_frame_bad_ = true;
            discarding_ = true;
            frame_.clear();
            return std::nullopt;
        }
        frame_.push_back(byte);
        return std::nullopt;
    }
    if (discarding_) {
        discarding_ = false;
        return std::nullopt;
    }
    if (frame_.empty()) return std::nullopt;  // the leading delimiter of a frame
    auto packet = finish_frame();
    frame_.clear();
    last_frame_bad_ = !packet;
    return packet;
}

std::optional<Packet> FrameDecoder::finish_frame()
{
    auto decoded = cobs_decode(frame_.data(), frame_.size());
    if (!decoded) {
        ++errors_.bad_cobs;
        return std::nullopt;
    }
    if (decoded->size() < 2 + 2) {
        ++errors_.too_short;
        return std::nullopt;
    }
    size_t n = decoded->size() - 2;
    uint16_t wire_crc = static_cast<uint16_t>((*decoded)[n] | ((*decoded)[n + 1] << 8));
    if (crc16(decoded->data(), n) != wire_crc) {
        ++errors_.bad_crc;
        return std::nullopt;
    }
    auto packet = parse(decoded->data(), n);
    if (!packet) ++errors_.bad_packet;
    return packet;
}

}  // namespace cpm::vehicle
