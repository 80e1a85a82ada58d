/* The serial protocol between vehicle_bridge and the car's microcontroller: framing (COBS between
 * zero bytes), CRC-16/CCITT-FALSE and the byte layout of the two packets (README.md of
 * vehicle_firmware_bridge). One C99 implementation, compiled into the AVR firmware and into the
 * host library cpm::vehicle, so the two ends cannot drift apart. No allocation, no stdio: every
 * buffer is the caller's. */
#ifndef CPM_SERIAL_H
#define CPM_SERIAL_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define CPM_SERIAL_VERSION 2u
#define CPM_SERIAL_KIND_STATE 0x01u
#define CPM_SERIAL_KIND_COMMAND 0x02u
/* Payload sizes: [version, kind, fields...], without the CRC. */
#define CPM_SERIAL_STATE_SIZE 38u
#define CPM_SERIAL_COMMAND_SIZE 12u
/* Longest COBS-encoded frame body a decoder accepts (the largest packet plus CRC, COBS overhead). */
#define CPM_SERIAL_MAX_FRAME 64u
/* Longest frame on the wire: two delimiters around COBS(state + CRC). */
#define CPM_SERIAL_MAX_WIRE (CPM_SERIAL_STATE_SIZE + 2u + 1u + 2u)

/* StatePacket.status bits. */
#define CPM_STATUS_BAD_CRC 0x01u       /* the last command frame had a bad CRC (or did not decode) */
#define CPM_STATUS_WATCHDOG_STOP 0x02u /* no valid command for the watchdog period: motor braked */
#define CPM_STATUS_WRONG_VEHICLE 0x04u /* the last command named another vehicle id (ignored) */
#define CPM_STATUS_BAD_COMMAND 0x08u   /* the last command's values were out of range (ignored) */
#define CPM_STATUS_STALE_COMMAND 0x10u /* the last command answered a state packet more than
                                          CPM_COMMAND_MAX_AGE_MS old: it waited in a backed-up
                                          line (ignored) */

/* A command answers a state packet (its tick); the controller ignores one that answers a packet
 * sent more than this long ago by its clock - applied that late, it would act on the past. */
#define CPM_COMMAND_MAX_AGE_MS 100u

/* Motor modes of a command. */
#define CPM_MOTOR_BRAKE 0u
#define CPM_MOTOR_FORWARD 1u
#define CPM_MOTOR_REVERSE 2u
/* Ranges a command must keep (a command outside them is not applied). */
#define CPM_MOTOR_PWM_MAX 1000u
#define CPM_SERVO_US_MIN 1000u
#define CPM_SERVO_US_MAX 2000u

/* Controller -> host, at the state rate (50 Hz). */
typedef struct cpm_state_packet {
    uint32_t tick;                /* controller time, ms since its start */
    uint8_t vehicle_id;
    int32_t odometer_steps;       /* hall ticks, signed (reverse counts down) */
    int16_t speed_mm_s;
    int16_t imu_yaw_e4;           /* 1e-4 rad, in (-pi, pi] */
    int16_t imu_yaw_rate_e3;      /* 1e-3 rad/s */
    int16_t accel_forward_mm_s2;
    int16_t accel_left_mm_s2;
    int16_t accel_up_mm_s2;
    uint16_t battery_mv;
    uint16_t motor_current_ma;
    uint16_t us_front_mm;         /* the sensor's maximum when nothing echoes */
    uint16_t us_left_mm;
    uint16_t us_right_mm;
    uint8_t status;               /* CPM_STATUS_* bits */
    uint32_t command_tick;        /* tick of the last valid command applied (a state's tick) */
} cpm_state_packet;

/* Host -> controller, once per state packet. */
typedef struct cpm_command_packet {
    uint32_t tick;                /* the tick of the state packet this command answers */
    uint8_t vehicle_id;           /* a command for another id is ignored */
    uint8_t motor_mode;           /* CPM_MOTOR_* */
    uint16_t motor_pwm;           /* duty cycle in 1/1000 (0..1000) */
    uint16_t servo_us;            /* servo pulse, 1000..2000 us, 1500 straight */
} cpm_command_packet;

/* CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection, no final xor;
 * cpm_crc16("123456789", 9) == 0x29B1. */
uint16_t cpm_crc16(const uint8_t* data, size_t size);

/* COBS (Cheshire & Baker 1999). Encode writes at most size + size/254 + 1 bytes, none of them
 * zero, and returns how many. Decode returns the decoded size, or -1 when the input is not
 * valid COBS; `out` holds at least `size` bytes. */
size_t cpm_cobs_encode(const uint8_t* data, size_t size, uint8_t* out);
long cpm_cobs_decode(const uint8_t* data, size_t size, uint8_t* out);

/* Payload bytes [version, kind, fields...] (little-endian), returns the size written
 * (CPM_SERIAL_STATE_SIZE or CPM_SERIAL_COMMAND_SIZE). */
size_t cpm_state_pack(const cpm_state_packet* p, uint8_t* out);
size_t cpm_command_pack(const cpm_command_packet* p, uint8_t* out);
/* Parse a payload. 0 on success; -1 on a wrong version, kind or length (or, for a command, a
 * motor mode that does not exist). */
int cpm_state_unpack(const uint8_t* data, size_t size, cpm_state_packet* p);
int cpm_command_unpack(const uint8_t* data, size_t size, cpm_command_packet* p);

/* One frame for the wire: 0x00, COBS(payload + CRC-16 little-endian), 0x00. `out` holds at
 * least size + 2 + (size + 2)/254 + 3 bytes; returns the frame's size. */
size_t cpm_frame_encode(const uint8_t* payload, size_t size, uint8_t* out);

/* What a byte fed to the decoder made of the frame it ends. */
enum cpm_decode_result {
    CPM_DECODE_NONE = 0,      /* nothing ended (or a frame's leading delimiter) */
    CPM_DECODE_PAYLOAD,       /* a frame with a good CRC: its payload is in decoder.payload */
    CPM_DECODE_OVERSIZE,      /* longer than any frame: dropped up to the next zero */
    CPM_DECODE_BAD_COBS,
    CPM_DECODE_TOO_SHORT,     /* shorter than a CRC plus a header (cut off) */
    CPM_DECODE_BAD_CRC
};

/* Turns a byte stream into payloads; resynchronises at the next zero byte after garbage, a
 * cut-off frame or a bad CRC; never hands out a payload whose CRC did not match. */
typedef struct cpm_decoder {
    uint8_t frame[CPM_SERIAL_MAX_FRAME];
    uint8_t payload[CPM_SERIAL_MAX_FRAME];
    uint8_t frame_size;
    uint8_t payload_size;
    uint8_t discarding;
} cpm_decoder;

void cpm_decoder_init(cpm_decoder* d);
/* Feeds one byte; returns what it ended (enum cpm_decode_result). */
int cpm_decoder_push(cpm_decoder* d, uint8_t byte);

#ifdef __cplusplus
}
#endif

#endif /* CPM_SERIAL_H */
