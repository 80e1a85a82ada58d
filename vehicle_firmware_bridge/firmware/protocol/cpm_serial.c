/* See cpm_serial.h. Plain C99 for avr-gcc and the host's compiler alike. */
#include "cpm_serial.h"

uint16_t cpm_crc16(const uint8_t* data, size_t size)
{
    uint16_t crc = 0xFFFFu;
    for (size_t i = 0; i < size; ++i) {
        crc = (uint16_t)(crc ^ ((uint16_t)data[i] << 8));
        for (uint8_t bit = 0; bit < 8; ++bit) {
            crc = (crc & 0x8000u) ? (uint16_t)((uint16_t)(crc << 1) ^ 0x1021u) : (uint16_t)(crc << 1);
        }
    }
    return crc;
}

size_t cpm_cobs_encode(const uint8_t* data, size_t size, uint8_t* out)
{
    size_t code_pos = 0, n = 1;
    uint8_t code = 1;
    for (size_t i = 0; i < size; ++i) {
        if (data[i] != 0) {
            out[n++] = data[i];
            if (++code != 0xFFu) continue;
        }
        /* a zero, or a full block of 254 non-zero bytes: close the block */
        out[code_pos] = code;
        code_pos = n++;
        code = 1;
    }
    out[code_pos] = code;
    return n;
}

long cpm_cobs_decode(const uint8_t* data, size_t size, uint8_t* out)
{
    size_t i = 0, n = 0;
    while (i < size) {
        uint8_t code = data[i];
        if (code == 0 || i + code > size) return -1;
        for (uint8_t k = 1; k < code; ++k) {
            if (data[i + k] == 0) return -1;
            out[n++] = data[i + k];
        }
        i += code;
        /* a block shorter than 254 bytes stood for a zero, except at the very end */
        if (code != 0xFFu && i < size) out[n++] = 0;
    }
    return (long)n;
}

static uint8_t* put16(uint8_t* out, uint16_t v)
{
    out[0] = (uint8_t)v;
    out[1] = (uint8_t)(v >> 8);
    return out + 2;
}

static uint8_t* put32(uint8_t* out, uint32_t v)
{
    out = put16(out, (uint16_t)v);
    return put16(out, (uint16_t)(v >> 16));
}

static uint16_t get16(const uint8_t** in)
{
    const uint8_t* p = *in;
    *in = p + 2;
    return (uint16_t)(p[0] | ((uint16_t)p[1] << 8));
}

static uint32_t get32(const uint8_t** in)
{
    uint32_t lo = get16(in);
    return lo | ((uint32_t)get16(in) << 16);
}

size_t cpm_state_pack(const cpm_state_packet* p, uint8_t* out)
{
    uint8_t* o = out;
    *o++ = CPM_SERIAL_VERSION;
    *o++ = CPM_SERIAL_KIND_STATE;
    o = put32(o, p->tick);
    *o++ = p->vehicle_id;
    o = put32(o, (uint32_t)p->odometer_steps);
    o = put16(o, (uint16_t)p->speed_mm_s);
    o = put16(o, (uint16_t)p->imu_yaw_e4);
    o = put16(o, (uint16_t)p->imu_yaw_rate_e3);
    o = put16(o, (uint16_t)p->accel_forward_mm_s2);
    o = put16(o, (uint16_t)p->accel_left_mm_s2);
    o = put16(o, (uint16_t)p->accel_up_mm_s2);
    o = put16(o, p->battery_mv);
    o = put16(o, p->motor_current_ma);
    o = put16(o, p->us_front_mm);
    o = put16(o, p->us_left_mm);
    o = put16(o, p->us_right_mm);
    *o++ = p->status;
    o = put32(o, p->command_tick);
    return (size_t)(o - out);
}

size_t cpm_command_pack(const cpm_command_packet* p, uint8_t* out)
{
    uint8_t* o = out;
    *o++ = CPM_SERIAL_VERSION;
    *o++ = CPM_SERIAL_KIND_COMMAND;
    o = put32(o, p->tick);
    *o++ = p->vehicle_id;
    *o++ = p->motor_mode;
    o = put16(o, p->motor_pwm);
    o = put16(o, p->servo_us);
    return (size_t)(o - out);
}

int cpm_state_unpack(const uint8_t* data, size_t size, cpm_state_packet* p)
{
    if (size != CPM_SERIAL_STATE_SIZE || data[0] != CPM_SERIAL_VERSION || data[1] != CPM_SERIAL_KIND_STATE) return -1;
    const uint8_t* in = data + 2;
    p->tick = get32(&in);
    p->vehicle_id = *in++;
    p->odometer_steps = (int32_t)get32(&in);
    p->speed_mm_s = (int16_t)get16(&in);
    p->imu_yaw_e4 = (int16_t)get16(&in);
    p->imu_yaw_rate_e3 = (int16_t)get16(&in);
    p->accel_forward_mm_s2 = (int16_t)get16(&in);
    p->accel_left_mm_s2 = (int16_t)get16(&in);
    p->accel_up_mm_s2 = (int16_t)get16(&in);
    p->battery_mv = get16(&in);
    p->motor_current_ma = get16(&in);
    p->us_front_mm = get16(&in);
    p->us_left_mm = get16(&in);
    p->us_right_mm = get16(&in);
    p->status = *in++;
    p->command_tick = get32(&in);
    return 0;
}

int cpm_command_unpack(const uint8_t* data, size_t size, cpm_command_packet* p)
{
    if (size != CPM_SERIAL_COMMAND_SIZE || data[0] != CPM_SERIAL_VERSION || data[1] != CPM_SERIAL_KIND_COMMAND) return -1;
    const uint8_t* in = data + 2;
    p->tick = get32(&in);
    p->vehicle_id = *in++;
    p->motor_mode = *in++;
    p->motor_pwm = get16(&in);
    p->servo_us = get16(&in);
    return p->motor_mode > CPM_MOTOR_REVERSE ? -1 : 0;
}

size_t cpm_frame_encode(const uint8_t* payload, size_t size, uint8_t* out)
{
    uint8_t body[CPM_SERIAL_MAX_FRAME];
    if (size + 2 > sizeof body) return 0;
    for (size_t i = 0; i < size; ++i) body[i] = payload[i];
    uint16_t crc = cpm_crc16(payload, size);
    body[size] = (uint8_t)crc;
    body[size + 1] = (uint8_t)(crc >> 8);
    out[0] = 0;
    size_t n = cpm_cobs_encode(body, size + 2, out + 1);
    out[n + 1] = 0;
    return n + 2;
}

void cpm_decoder_init(cpm_decoder* d)
{
    d->frame_size = 0;
    d->payload_size = 0;
    d->discarding = 0;
}

static int finish_frame(cpm_decoder* d)
{
    long n = cpm_cobs_decode(d->frame, d->frame_size, d->payload);
    if (n < 0) return CPM_DECODE_BAD_COBS;
    if (n < 2 + 2) return CPM_DECODE_TOO_SHORT;
    n -= 2;
    uint16_t wire_crc = (uint16_t)(d->payload[n] | ((uint16_t)d->payload[n + 1] << 8));
    if (cpm_crc16(d->payload, (size_t)n) != wire_crc) return CPM_DECODE_BAD_CRC;
    d->payload_size = (uint8_t)n;
    return CPM_DECODE_PAYLOAD;
}

int cpm_decoder_push(cpm_decoder* d, uint8_t byte)
{
    if (byte != 0) {
        if (d->discarding) return CPM_DECODE_NONE;
        if (d->frame_size == CPM_SERIAL_MAX_FRAME) {
            d->discarding = 1;
            d->frame_size = 0;
            return CPM_DECODE_OVERSIZE;
        }
        d->frame[d->frame_size++] = byte;
        return CPM_DECODE_NONE;
    }
    if (d->discarding) {
        d->discarding = 0;
        return CPM_DECODE_NONE;
    }
    if (d->frame_size == 0) return CPM_DECODE_NONE; /* the leading delimiter of a frame */
    int result = finish_frame(d);
    d->frame_size = 0;
    return result;
}
