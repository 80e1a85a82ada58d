/* cpm's car firmware for an ATmega2560 (board.h): speaks vehicle_bridge's serial protocol
 * (protocol/cpm_serial.h, the same C code the bridge runs), drives the motor and the steering
 * servo from valid commands, reports odometer, speed, IMU, battery, motor current and the three
 * rangers in a state packet every 20 ms, and brakes when no valid command came for 250 ms.
 * A frame with a bad CRC or length, a command for another car, with values out of range or
 * answering a state packet over CPM_COMMAND_MAX_AGE_MS old is never acted on; the hardware
 * watchdog resets a loop that stops. */
#include "board.h"
#include "cpm_serial.h"
#include "hw.h"

#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/wdt.h>

/* The hardware watchdog survives a reset on this chip: off first thing, before main. */
void early_wdt_off(void) __attribute__((naked, used, section(".init3")));
void early_wdt_off(void)
{
    MCUSR = 0;
    wdt_disable();
}

static cpm_decoder decoder;
static uint8_t vehicle_id;
static uint8_t status;
static uint32_t command_tick;
static uint32_t last_command_ms;
static uint8_t watchdog_stopped;
static uint8_t imu_ok;
static float yaw_rad;           /* integrated from the gyro */
static int16_t accel[3], gyro[3];
static uint32_t last_imu_half_us;
static uint32_t served_ms;

static uint8_t busy(void) { return hw_millis() != served_ms || hw_serial_available() || hw_imu_ready(); }

static void on_command(const cpm_command_packet* c)
{
    if (c->vehicle_id != vehicle_id) {
        status |= CPM_STATUS_WRONG_VEHICLE;
        return;
    }
    status &= (uint8_t)~CPM_STATUS_WRONG_VEHICLE;
    if (c->motor_pwm > CPM_MOTOR_PWM_MAX || c->servo_us < CPM_SERVO_US_MIN || c->servo_us > CPM_SERVO_US_MAX) {
        status |= CPM_STATUS_BAD_COMMAND;
        return;
    }
    if ((uint32_t)(hw_millis() - c->tick) > CPM_COMMAND_MAX_AGE_MS) {
        status |= CPM_STATUS_STALE_COMMAND; /* also one from before a restart: its tick is ahead */
        return;
    }
    status &= (uint8_t)~(CPM_STATUS_BAD_COMMAND | CPM_STATUS_STALE_COMMAND | CPM_STATUS_WATCHDOG_STOP);
    watchdog_stopped = 0;
    command_tick = c->tick;
    last_command_ms = hw_millis();
    hw_motor(c->motor_mode, c->motor_pwm);
    hw_servo(c->servo_us);
}

static void read_line(void)
{
    for (int byte; (byte = hw_serial_read()) >= 0;) {
        int result = cpm_decoder_push(&decoder, (uint8_t)byte);
        if (result == CPM_DECODE_NONE) continue;
        cpm_command_packet command;
        if (result == CPM_DECODE_PAYLOAD &&
            cpm_command_unpack(decoder.payload, decoder.payload_size, &command) == 0) {
            status &= (uint8_t)~CPM_STATUS_BAD_CRC;
            on_command(&command);
        } else {
            status |= CPM_STATUS_BAD_CRC;
        }
    }
}

static void watch_commands(uint32_t now)
{
    if (!watchdog_stopped && now - last_command_ms > COMMAND_WATCHDOG_MS) {
        watchdog_stopped = 1;
        status |= CPM_STATUS_WATCHDOG_STOP;
        hw_motor(CPM_MOTOR_BRAKE, 0);
        hw_servo(1500);
    }
}

static void take_imu(void)
{
    const int8_t got = hw_imu_take(accel, gyro);
    if (got == 0) return;
    if (got < 0) {
        imu_ok = 0;
        return;
    }
    const uint32_t now = hw_halfmicros();
    if (imu_ok) {
        const float rad_per_lsb = 3.14159265f / 180.0f / IMU_GYRO_LSB_PER_DPS;
        yaw_rad += (float)gyro[2] * rad_per_lsb * (float)(now - last_imu_half_us) * 0.5e-6f;
        if (yaw_rad > 3.14159265f) yaw_rad -= 6.2831853f;
        if (yaw_rad <= -3.14159265f) yaw_rad += 6.2831853f;
    }
    imu_ok = 1;
    last_imu_half_us = now;
}

static int16_t mm_s2(int16_t raw) { return (int16_t)((float)raw * 9810.0f / IMU_ACCEL_LSB_PER_G); }

static void send_state(uint32_t now)
{
    cpm_state_packet s;
    s.tick = now;
    s.vehicle_id = vehicle_id;
    s.odometer_steps = hw_odometer();
    s.speed_mm_s = hw_speed_mm_s();
    s.imu_yaw_e4 = (int16_t)(yaw_rad * 1e4f);
    s.imu_yaw_rate_e3 = (int16_t)((float)gyro[2] * (3.14159265f / 180.0f * 1000.0f) / IMU_GYRO_LSB_PER_DPS);
    s.accel_forward_mm_s2 = mm_s2(accel[0]);
    s.accel_left_mm_s2 = mm_s2(accel[1]);
    s.accel_up_mm_s2 = mm_s2(accel[2]);
    s.battery_mv = (uint16_t)(hw_adc_mv(0) * BATTERY_DIVIDER);
    s.motor_current_ma = (uint16_t)((uint32_t)hw_adc_mv(1) * 1000u / CURRENT_MV_PER_A);
    uint16_t ranges[3];
    hw_rangers_read(ranges);
    s.us_front_mm = ranges[0];
    s.us_left_mm = ranges[1];
    s.us_right_mm = ranges[2];
    s.status = status;
    s.command_tick = command_tick;

    uint8_t payload[CPM_SERIAL_STATE_SIZE];
    uint8_t frame[CPM_SERIAL_MAX_WIRE + 4];
    size_t n = cpm_frame_encode(payload, cpm_state_pack(&s, payload), frame);
    (void)hw_serial_write(frame, (uint8_t)n); /* a line still busy with the last one skips this one */
}

int main(void)
{
    hw_init();
    cpm_decoder_init(&decoder);
    vehicle_id = hw_vehicle_id();
    wdt_enable(WDTO_120MS);
    sei();
    imu_ok = hw_imu_init() == 0;
    for (;;) {
        wdt_reset();
        read_line();
        take_imu();
        uint32_t now = hw_millis();
        while (served_ms != now) {
            ++served_ms;
            watch_commands(served_ms);
            if (served_ms % IMU_PERIOD_MS == 0) hw_imu_start();
            if (served_ms % RANGER_PERIOD_MS == RANGER_PERIOD_MS / 2) hw_rangers_fire();
            if (served_ms % STATE_PERIOD_MS == 0) send_state(served_ms);
            read_line();
        }
        hw_idle(busy);
    }
}
