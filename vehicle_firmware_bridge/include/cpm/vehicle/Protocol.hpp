#pragma once
#include <cpm/vehicle/cpm_serial.h>

#include <cstddef>
#include <cstdint>
#include <optional>
#include <variant>
#include <vector>

/// The serial protocol between vehicle_bridge and the car's microcontroller (README.md in
/// this folder has the byte layout). Every packet is [version, kind, fields...] with
/// little-endian fields of fixed width, then a CRC-16/CCITT-FALSE, COBS-encoded between two
/// zero bytes. The bytes are made and checked by the C code the car's firmware runs too
/// (cpm/vehicle/cpm_serial.h, from firmware/protocol/); these are its C++ faces.
namespace cpm::vehicle {

constexpr uint8_t kProtocolVersion = CPM_SERIAL_VERSION;
/// A command answers a state packet; the AVR firmware ignores one answering a packet sent more
/// than this long ago by its clock (it waited in a backed-up line).
constexpr uint32_t kCommandMaxAgeMs = CPM_COMMAND_MAX_AGE_MS;

/// Status bits of StatePacket::status.
enum StatusFlags : uint8_t {
    kStatusBadCrc = 1u << 0,         ///< the last command frame had a bad CRC (or did not decode)
    kStatusWatchdogStop = 1u << 1,   ///< no valid command for the watchdog period: motor braked
    kStatusWrongVehicle = 1u << 2,   ///< the last command named another vehicle id (ignored)
    kStatusBadCommand = 1u << 3,     ///< the last command's values were out of range (the AVR firmware ignores it)
    kStatusStaleCommand = 1u << 4,   ///< the last command answered a state over kCommandMaxAgeMs old (the AVR firmware ignores it)
};

enum class MotorMode : uint8_t { brake = 0, forward = 1, reverse = 2 };

/// Controller → host, 50 Hz. Units as the firmware measures them.
struct StatePacket
{
    uint32_t tick = 0;                 ///< controller time, ms since its start
    uint8_t vehicle_id = 0;            ///< the car this controller belongs to
    int32_t odometer_steps = 0;        ///< hall ticks, signed (reverse counts down)
    int16_t speed_mm_s = 0;            ///< mm/s, signed
    int16_t imu_yaw_e4 = 0;            ///< 1e-4 rad, in (-pi, pi]
    int16_t imu_yaw_rate_e3 = 0;       ///< 1e-3 rad/s
    int16_t accel_forward_mm_s2 = 0;   ///< mm/s^2
    int16_t accel_left_mm_s2 = 0;      ///< mm/s^2
    int16_t accel_up_mm_s2 = 0;        ///< mm/s^2
    uint16_t battery_mv = 0;           ///< mV
    uint16_t motor_current_ma = 0;     ///< mA
    uint16_t us_front_mm = 0;          ///< mm, the sensor's maximum when nothing echoes
    uint16_t us_left_mm = 0;           ///< mm
    uint16_t us_right_mm = 0;          ///< mm
    uint8_t status = 0;                ///< StatusFlags
    uint32_t command_tick = 0;         ///< tick of the last valid command applied (the state it answered)
    bool operator==(const StatePacket&) const;
};

/// Host → controller, once per state packet.
struct CommandPacket
{
    uint32_t tick = 0;                 ///< the tick of the state packet it answers (echoed in StatePacket)
    uint8_t vehicle_id = 0;            ///< the controller ignores commands for another id
    MotorMode motor_mode = MotorMode::brake;
    uint16_t motor_pwm = 0;            ///< duty cycle in 1/1000 (0..1000)
    uint16_t servo_us = 1500;          ///< servo pulse width in µs (1000..2000, 1500 = straight)
    bool operator==(const CommandPacket&) const;
};

using Packet = std::variant<StatePacket, CommandPacket>;

/// CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection, no final xor;
/// crc16("123456789") == 0x29B1.
uint16_t crc16(const uint8_t* data, size_t size);

/// COBS (Cheshire & Baker 1999): the output holds no zero byte; size <= n + n/254 + 1.
std::vector<uint8_t> cobs_encode(const uint8_t* data, size_t size);
/// Inverse of cobs_encode; nullopt when the input is not valid COBS.
std::optional<std::vector<uint8_t>> cobs_decode(const uint8_t* data, size_t size);

/// The payload bytes [version, kind, fields...] without CRC or framing.
std::vector<uint8_t> serialize(const Packet& packet);
/// Parses a payload; nullopt on a wrong version, an unknown kind or a wrong length.
std::optional<Packet> parse(const uint8_t* data, size_t size);

/// One frame ready for the wire: 0x00, COBS(payload + CRC-16 little-endian), 0x00.
std::vector<uint8_t> encode_frame(const Packet& packet);

/// What the decoder threw away, by reason.
struct DecoderErrors
{
    uint64_t oversize = 0;     ///< frames longer than any packet (garbage, lost delimiter)
    uint64_t bad_cobs = 0;     ///< frames that are not valid COBS
    uint64_t too_short = 0;    ///< frames shorter than a CRC plus a header (cut off)
    uint64_t bad_crc = 0;      ///< CRC mismatch
    uint64_t bad_packet = 0;   ///< good CRC but wrong version, unknown kind or wrong length
    uint64_t total() const { return oversize + bad_cobs + too_short + bad_crc + bad_packet; }
};

/// Turns a byte stream into packets. Resynchronises at the next zero byte after garbage, a
/// cut-off frame or a bad CRC; never returns a packet whose CRC did not match. Not thread-safe.
class FrameDecoder
{
public:
    /// Feeds bytes; calls on_packet for every good packet in them, in order.
    template <class F>
    void feed(const uint8_t* data, size_t size, F&& on_packet)
    {
        for (size_t i = 0; i < size; ++i) {
            if (auto packet = push(data[i])) on_packet(*packet);
        }
    }
    FrameDecoder();
    /// Feeds one byte; a packet when this byte completed a good frame.
    std::optional<Packet> push(uint8_t byte);

    const DecoderErrors& errors() const { return errors_; }
    /// True when the last frame that ended was rejected (cleared by a good frame).
    bool last_frame_bad() const { return last_frame_bad_; }

    /// Longest encoded frame body accepted (the largest packet plus CRC, COBS overhead).
    static constexpr size_t kMaxFrame = CPM_SERIAL_MAX_FRAME;

private:
    cpm_decoder decoder_;
    bool last_frame_bad_ = false;
    DecoderErrors errors_;
};

}  // namespace cpm::vehicle
