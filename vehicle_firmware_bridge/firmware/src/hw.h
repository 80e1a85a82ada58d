/* The board's peripherals as the firmware uses them (pins and rates: board.h). */
#ifndef CPM_FIRMWARE_HW_H
#define CPM_FIRMWARE_HW_H

#include <stdint.h>

/* Every peripheral set up; interrupts still off. */
void hw_init(void);

/* Milliseconds since start (Timer0); the time in 0.5 us steps (Timer3, wraps every 35 min). */
uint32_t hw_millis(void);
uint32_t hw_halfmicros(void);

/* Serial line. Received bytes wait in a ring; a byte that finds the ring full is dropped and
 * counted (a flooding host cannot block the loop). Writing queues the bytes for the transmit
 * interrupt; returns 0 when they did not fit (nothing is queued then). */
int hw_serial_read(void);            /* the next byte, or -1 */
uint8_t hw_serial_available(void);  /* bytes wait in the ring */
uint8_t hw_serial_write(const uint8_t* data, uint8_t size);
uint16_t hw_serial_dropped(void);

/* Motor: mode CPM_MOTOR_*, duty 0..1000; servo pulse 1000..2000 us. */
void hw_motor(uint8_t mode, uint16_t duty);
void hw_servo(uint16_t pulse_us);

/* Odometer: signed hall ticks so far, and the speed (mm/s) from the time between edges. */
int32_t hw_odometer(void);
int16_t hw_speed_mm_s(void);

/* Rangers: fire all three now; the distances (mm) of the last complete echoes, the maximum for
 * one that did not echo in the last period. */
void hw_rangers_fire(void);
void hw_rangers_read(uint16_t mm[3]);

/* ADC in millivolts at the pin: channel 0 battery, 1 motor current. */
uint16_t hw_adc_mv(uint8_t channel);

/* IMU: configured once at start (blocking; 0 when it answered). A read is started and runs in
 * the TWI interrupt; hw_imu_take then gives 1 with the raw accelerometer (x, y, z) and gyro
 * (x, y, z) words once it finished, -1 when the device did not answer, 0 while it is under way
 * (or none was started). hw_imu_ready: a result waits. */
int8_t hw_imu_init(void);
void hw_imu_start(void);
int8_t hw_imu_take(int16_t accel[3], int16_t gyro[3]);
uint8_t hw_imu_ready(void);

/* The vehicle id from EEPROM. */
uint8_t hw_vehicle_id(void);

/* Sleep until the next interrupt unless `busy` says there is work (called with interrupts on). */
void hw_idle(uint8_t (*busy)(void));

#endif
