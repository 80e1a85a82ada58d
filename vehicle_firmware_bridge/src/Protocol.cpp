#include <cpm/vehicle/Protocol.hpp>


namespace cpm::vehicle {
namespace {

// The framing, CRC and byte layout are the C code the firmware runs too (firmware/protocol/):
// here they are only wrapped in C++ types.
cpm_state_packet to_c(const StatePacket& p)
{
    return {p.tick, p.vehicle_id, p.odometer_steps, p.speed_mm_s, p.imu_yaw_e4, p.imu_yaw_rate_e3,
            p.accel_forward_mm_s2, p.accel_left_mm_s2, p.accel_up_mm_s2, p.battery_mv, p.motor_current_ma,
            p.us_front_mm, p.us_left_mm, p.us_right_mm, p.status, p.command_tick};
}

StatePacket from_c(const cpm_state_packet& c)
{
    StatePacket p;
    p.tick = c.tick;
    p.vehicle_id = c.vehicle_id;
    p.odometer_steps = c.odometer_steps;
    p.speed_mm_s = c.speed_mm_s;
    p.imu_yaw_e4 = c.imu_yaw_e4;
    p.imu_yaw_rate_e3 = c.imu_yaw_rate_e3;
    p.accel_forward_mm_s2 = c.accel_forward_mm_s2;
    p.accel_left_mm_s2 = c.accel_left_mm_s2;
    p.accel_up_mm_s2 = c.accel_up_mm_s2;
    p.battery_mv = c.battery_mv;
    p.motor_current_ma = c.motor_current_ma;
    p.us_front_mm = c.us_front_mm;
    p.us_left_mm = c.us_left_mm;
    p.us_right_mm = c.us_right_mm;
    p.status = c.status;
    p.command_tick = c.command_tick;
    return p;
}

cpm_command_packet to_c(const CommandPacket& p)
{
    return {p.tick, p.vehicle_id, static_cast<uint8_t>(p.motor_mode), p.motor_pwm, p.servo_us};
}

std::vector<uint8_t> serialize_state(const StatePacket& p)
{
    std::vector<uint8_t> out(CPM_SERIAL_STATE_SIZE);
    const auto c = to_c(p);
    out.resize(cpm_state_pack(&c, out.data()));
    return out;
}

std::vector<uint8_t> serialize_command(const CommandPacket& p)
{
    std::vector<uint8_t> out(CPM_SERIAL_COMMAND_SIZE);
    const auto c = to_c(p);
    out.resize(cpm_command_pack(&c, out.data()));
    return out;
}

}  // namespace

bool StatePacket::operator==(const StatePacket& o) const { return serialize_state(*this) == serialize_state(o); }
bool CommandPacket::operator==(const CommandPacket& o) const { return serialize_command(*this) == serialize_command(o); }

uint16_t crc16(const uint8_t* data, size_t size) { return cpm_crc16(data, size); }

std::vector<uint8_t> cobs_encode(const uint8_t* data, size_t size)
{
    std::vector<uint8_t> out(size + size / 254 + 1);
    out.resize(cpm_cobs_encode(data, size, out.data()));
    return out;
}

std::optional<std::vector<uint8_t>> cobs_decode(const uint8_t* data, size_t size)
{
    std::vector<uint8_t> out(size);
    const long n = cpm_cobs_decode(data, size, out.data());
    if (n < 0) return std::nullopt;
    out.resize(size_t(n));
    return out;
}

std::vector<uint8_t> serialize(const Packet& packet)
{
    if (auto* state = std::get_if<StatePacket>(&packet)) return serialize_state(*state);
    return serialize_command(std::get<CommandPacket>(packet));
}

std::optional<Packet> parse(const uint8_t* data, size_t size)
{
    if (size < 2) return std::nullopt;
    if (cpm_state_packet s; cpm_state_unpack(data, size, &s) == 0) return Packet(from_c(s));
    if (cpm_command_packet c; cpm_command_unpack(data, size, &c) == 0) {
        return Packet(CommandPacket{c.tick, c.vehicle_id, static_cast<MotorMode>(c.motor_mode), c.motor_pwm, c.servo_us});
    }
    return std::nullopt;
}

std::vector<uint8_t> encode_frame(const Packet& packet)
{
    const auto bytes = serialize(packet);
    std::vector<uint8_t> frame(CPM_SERIAL_MAX_WIRE + 4);
    frame.resize(cpm_frame_encode(bytes.data(), bytes.size(), frame.data()));
    return frame;
}

FrameDecoder::FrameDecoder() { cpm_decoder_init(&decoder_); }

std::optional<Packet> FrameDecoder::push(uint8_t byte)
{
    switch (cpm_decoder_push(&decoder_, byte)) {
    case CPM_DECODE_NONE:
        return std::nullopt;
    case CPM_DECODE_OVERSIZE:
        ++errors_.oversize;
        break;
    case CPM_DECODE_BAD_COBS:
        ++errors_.bad_cobs;
        break;
    case CPM_DECODE_TOO_SHORT:
        ++errors_.too_short;
        break;
    case CPM_DECODE_BAD_CRC:
        ++errors_.bad_crc;
        break;
    default: {
        auto packet = parse(decoder_.payload, decoder_.payload_size);
        if (!packet) ++errors_.bad_packet;
        last_frame_bad_ = !packet;
        return packet;
    }
    }
    last_frame_bad_ = true;
    return std::nullopt;
}

}  // namespace cpm::vehicle
