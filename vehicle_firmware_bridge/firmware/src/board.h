/* The car's microcontroller board: an ATmega2560 at 16 MHz (as on cpm_lab's cars), which pins
 * and timers do what, and the car's constants the firmware needs. firmware_hil plays the car
 * against exactly these pins; README.md of this folder has the same table for wiring a board. */
#ifndef CPM_FIRMWARE_BOARD_H
#define CPM_FIRMWARE_BOARD_H

#include <stdint.h>

/* USART0 (PE0 RXD0, PE1 TXD0; the USB serial of a Mega board): 115200 8N1, U2X. */
#define BOARD_BAUD 115200UL
/* Timer0, CTC at 1 kHz: the millisecond tick (state packets, watchdog). */
/* Timer1, fast PWM at 50 Hz on OC1A (PB5, Mega pin 11): the steering servo, 0.5 us steps. */
#define SERVO_TOP 39999u            /* 2 MHz / 40000 = 50 Hz */
/* Timer3, free-running at 2 MHz: the microsecond clock of hall edges and echo pulses. */
/* Timer4, fast PWM at 16 kHz on OC4A (PH3, Mega pin 6): the motor driver's PWM input, duty in
 * 1/1000 exactly (TOP 999). */
#define MOTOR_TOP 999u
/* Motor driver direction inputs (a VNH-type H bridge): PA0 = INA, PA1 = INB (Mega pins 22, 23).
 * INA=1 INB=0 forward, INA=0 INB=1 reverse, both 0: brake to ground. */
#define MOTOR_DIR_PORT PORTA
#define MOTOR_DIR_DDR DDRA
#define MOTOR_INA 0
#define MOTOR_INB 1
/* Hall odometer: INT4 (PE4, Mega pin 2), a rising edge per tick. */
#define ODOMETER_TICKS_PER_METRE 600u
/* Three HC-SR04-type rangers, triggered together: triggers PC0..PC2 (Mega pins 37, 36, 35),
 * echoes PB0..PB2 (PCINT0..2, Mega pins 53, 52, 51); front, left, right. */
#define RANGER_COUNT 3
#define RANGER_MIN_MM 20u
#define RANGER_MAX_MM 3000u          /* reported when nothing echoes */
#define SOUND_MM_PER_MS 343u         /* speed of sound, mm/ms; the echo pulse is the round trip */
/* ADC, reference AVCC = 5 V: ADC0 (PF0) battery through a 1:2 divider, ADC1 (PF1) motor current
 * sensor at 0.5 V/A. */
#define ADC_REFERENCE_MV 5000UL
#define BATTERY_DIVIDER 2UL
#define CURRENT_MV_PER_A 500UL
/* IMU: an MPU-6050-type gyro/accelerometer on TWI (SDA PD1, SCL PD0) at 400 kHz, address 0x68;
 * accelerometer +-4 g (8192 LSB/g), gyro +-500 deg/s (65.5 LSB per deg/s); its x axis forward,
 * y left, z up. */
#define IMU_ADDRESS 0x68u
#define IMU_ACCEL_LSB_PER_G 8192.0f
#define IMU_GYRO_LSB_PER_DPS 65.5f
/* Rates: a state packet every 20 ms, the IMU read every 5 ms, the rangers fired every 20 ms. */
#define STATE_PERIOD_MS 20u
#define IMU_PERIOD_MS 5u
#define RANGER_PERIOD_MS 20u
/* No valid command for this long: the motor brakes (as firmware_sim). */
#define COMMAND_WATCHDOG_MS 250u
/* The vehicle id lives in EEPROM byte 0 (avrdude -U eeprom:w:0x07:m gives car 7). */
#define EEPROM_VEHICLE_ID 0

#endif
