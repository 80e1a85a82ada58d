/* Drivers of the board's peripherals (board.h): interrupt-driven serial line, millisecond and
 * microsecond clocks, motor and servo PWM, hall odometer, ultrasonic echo timing, ADC, TWI. */
#include "hw.h"

#include "board.h"
#include "cpm_serial.h"

#include <avr/eeprom.h>
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>
#include <util/atomic.h>
#include <util/delay.h>

uint8_t EEMEM ee_vehicle_id = 1;

static volatile uint32_t millis_;
static volatile uint16_t t3_high_;

/* --- serial ------------------------------------------------------------------------------ */
#define RX_RING 128u
#define TX_RING 128u
static volatile uint8_t rx_[RX_RING], tx_[TX_RING];
static volatile uint8_t rx_head_, rx_tail_, tx_head_, tx_tail_;
static volatile uint16_t rx_dropped_;

ISR(USART0_RX_vect)
{
    uint8_t byte = UDR0;
    uint8_t next = (uint8_t)((rx_head_ + 1u) % RX_RING);
    if (next == rx_tail_) {
        ++rx_dropped_;
        return;
    }
    rx_[rx_head_] = byte;
    rx_head_ = next;
}

ISR(USART0_UDRE_vect)
{
    if (tx_tail_ == tx_head_) {
        UCSR0B &= (uint8_t)~(1u << UDRIE0);
        return;
    }
    UDR0 = tx_[tx_tail_];
    tx_tail_ = (uint8_t)((tx_tail_ + 1u) % TX_RING);
}

int hw_serial_read(void)
{
    if (rx_tail_ == rx_head_) return -1;
    uint8_t byte = rx_[rx_tail_];
    rx_tail_ = (uint8_t)((rx_tail_ + 1u) % RX_RING);
    return byte;
}

uint8_t hw_serial_available(void) { return rx_tail_ != rx_head_; }

uint8_t hw_serial_write(const uint8_t* data, uint8_t size)
{
    uint8_t used = (uint8_t)((tx_head_ + TX_RING - tx_tail_) % TX_RING);
    if ((uint16_t)used + size >= TX_RING) return 0;
    for (uint8_t i = 0; i < size; ++i) {
        tx_[tx_head_] = data[i];
        tx_head_ = (uint8_t)((tx_head_ + 1u) % TX_RING);
    }
    UCSR0B |= (1u << UDRIE0);
    return 1;
}

uint16_t hw_serial_dropped(void)
{
    uint16_t n;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { n = rx_dropped_; }
    return n;
}

/* --- clocks -------------------------------------------------------------------------------- */
ISR(TIMER0_COMPA_vect) { ++millis_; }
ISR(TIMER3_OVF_vect) { ++t3_high_; }

uint32_t hw_millis(void)
{
    uint32_t m;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { m = millis_; }
    return m;
}

/* Called with interrupts off (from an ISR or an atomic block). */
static uint32_t halfmicros_locked(void)
{
    uint16_t low = TCNT3;
    uint16_t high = t3_high_;
    if ((TIFR3 & (1u << TOV3)) && low < 0x8000u) ++high; /* wrapped, its interrupt still pending */
    return ((uint32_t)high << 16) | low;
}

uint32_t hw_halfmicros(void)
{
    uint32_t t;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { t = halfmicros_locked(); }
    return t;
}

/* --- motor and servo ----------------------------------------------------------------------- */
static volatile int8_t direction_ = 1; /* the sign hall ticks count with */

void hw_motor(uint8_t mode, uint16_t duty)
{
    if (duty > CPM_MOTOR_PWM_MAX) duty = CPM_MOTOR_PWM_MAX;
    if (mode == CPM_MOTOR_FORWARD) {
        MOTOR_DIR_PORT = (uint8_t)((MOTOR_DIR_PORT & ~(1u << MOTOR_INB)) | (1u << MOTOR_INA));
        direction_ = 1;
    } else if (mode == CPM_MOTOR_REVERSE) {
        MOTOR_DIR_PORT = (uint8_t)((MOTOR_DIR_PORT & ~(1u << MOTOR_INA)) | (1u << MOTOR_INB));
        direction_ = -1;
    } else {
        MOTOR_DIR_PORT &= (uint8_t)~((1u << MOTOR_INA) | (1u << MOTOR_INB));
        duty = 0;
    }
    OCR4A = duty;
}

void hw_servo(uint16_t pulse_us)
{
    if (pulse_us < CPM_SERVO_US_MIN) pulse_us = CPM_SERVO_US_MIN;
    if (pulse_us > CPM_SERVO_US_MAX) pulse_us = CPM_SERVO_US_MAX;
    OCR1A = (uint16_t)(pulse_us * 2u);
}

/* --- odometer ------------------------------------------------------------------------------ */
static volatile int32_t ticks_;
static volatile uint16_t edges_since_;
static volatile uint32_t last_edge_;
static uint32_t speed_edge_;   /* the edge the last speed was measured up to */
static uint8_t speed_valid_;
static int16_t speed_;

ISR(INT4_vect)
{
    ticks_ += direction_;
    ++edges_since_;
    last_edge_ = halfmicros_locked();
}

int32_t hw_odometer(void)
{
    int32_t t;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { t = ticks_; }
    return t;
}

int16_t hw_speed_mm_s(void)
{
    uint16_t n;
    uint32_t last, now;
    int8_t sign;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        n = edges_since_;
        edges_since_ = 0;
        last = last_edge_;
        now = halfmicros_locked();
        sign = direction_;
    }
    const float mm_per_tick = 1000.0f / (float)ODOMETER_TICKS_PER_METRE;
    if (n > 0) {
        /* n ticks between the edge the last figure ended at and the newest edge */
        if (speed_valid_ && last != speed_edge_) {
            float s = (float)n * mm_per_tick / ((float)(last - speed_edge_) * 0.5e-6f);
            speed_ = (int16_t)(sign * (s > 32000.0f ? 32000.0f : s));
        }
        speed_edge_ = last;
        speed_valid_ = 1;
    } else if (speed_valid_) {
        /* no edge yet: the car is at most as fast as one tick over the time since the last */
        float bound = mm_per_tick / ((float)(now - speed_edge_) * 0.5e-6f);
        float s = speed_ < 0 ? -(float)speed_ : (float)speed_;
        if (bound < s) speed_ = (int16_t)(sign * bound);
        if (now - speed_edge_ > 400000u) speed_ = 0; /* 200 ms without an edge: standing */
    }
    return speed_;
}

/* --- rangers ------------------------------------------------------------------------------- */
static volatile uint32_t echo_rise_[RANGER_COUNT];
static volatile uint16_t echo_mm_[RANGER_COUNT];
static volatile uint8_t echo_done_, echo_high_;
static uint16_t ranger_mm_[RANGER_COUNT] = {RANGER_MAX_MM, RANGER_MAX_MM, RANGER_MAX_MM};

ISR(PCINT0_vect)
{
    uint32_t now = halfmicros_locked();
    uint8_t pins = PINB & 0x07u;
    uint8_t changed = (uint8_t)(pins ^ echo_high_);
    echo_high_ = pins;
    for (uint8_t i = 0; i < RANGER_COUNT; ++i) {
        uint8_t bit = (uint8_t)(1u << i);
        if (!(changed & bit)) continue;
        if (pins & bit) {
            echo_rise_[i] = now;
        } else {
            /* the pulse (in 0.5 us steps) is the round trip: mm = us * 343 / 1000 / 2, rounded */
            uint32_t half_us = now - echo_rise_[i];
            uint32_t mm = (half_us * SOUND_MM_PER_MS + 2000u) / 4000u;
            echo_mm_[i] = (uint16_t)(mm > RANGER_MAX_MM ? RANGER_MAX_MM : (mm < RANGER_MIN_MM ? RANGER_MIN_MM : mm));
            echo_done_ |= bit;
        }
    }
}

void hw_rangers_fire(void)
{
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        for (uint8_t i = 0; i < RANGER_COUNT; ++i) {
            ranger_mm_[i] = (echo_done_ & (1u << i)) ? echo_mm_[i] : RANGER_MAX_MM;
        }
        echo_done_ = 0;
    }
    PORTC |= 0x07u;
    _delay_us(10);
    PORTC &= (uint8_t)~0x07u;
}

void hw_rangers_read(uint16_t mm[3])
{
    for (uint8_t i = 0; i < RANGER_COUNT; ++i) mm[i] = ranger_mm_[i];
}

/* --- ADC ----------------------------------------------------------------------------------- */
uint16_t hw_adc_mv(uint8_t channel)
{
    ADMUX = (uint8_t)((1u << REFS0) | (channel & 0x07u)); /* AVCC reference */
    ADCSRB &= (uint8_t)~(1u << MUX5);
    ADCSRA |= (1u << ADSC);
    while (ADCSRA & (1u << ADSC)) {
    }
    uint16_t raw = ADC;
    return (uint16_t)(((uint32_t)raw * ADC_REFERENCE_MV + 512u) / 1024u);
}

/* --- TWI (IMU) ----------------------------------------------------------------------------- */
/* Waits for TWINT; gives up after ~2 ms so a missing device never stalls the loop. */
static int8_t twi_wait(void)
{
    for (uint16_t n = 0; n < 4000u; ++n) {
        if (TWCR & (1u << TWINT)) return 0;
        _delay_us(0.5);
    }
    return -1;
}

static int8_t twi_command(uint8_t twcr, uint8_t expected)
{
    TWCR = twcr;
    if (twi_wait() < 0) return -1;
    return (TWSR & 0xF8u) == expected ? 0 : -1;
}

static void twi_stop(void) { TWCR = (uint8_t)((1u << TWINT) | (1u << TWEN) | (1u << TWSTO)); }

static int8_t twi_start(uint8_t address_rw, uint8_t repeated)
{
    if (twi_command((uint8_t)((1u << TWINT) | (1u << TWSTA) | (1u << TWEN)), repeated ? 0x10u : 0x08u) < 0) return -1;
    TWDR = address_rw;
    return twi_command((uint8_t)((1u << TWINT) | (1u << TWEN)), (address_rw & 1u) ? 0x40u : 0x18u);
}

static int8_t twi_write(uint8_t byte)
{
    TWDR = byte;
    return twi_command((uint8_t)((1u << TWINT) | (1u << TWEN)), 0x28u);
}

static int8_t imu_write(uint8_t reg, uint8_t value)
{
    int8_t ok = twi_start((uint8_t)(IMU_ADDRESS << 1), 0) == 0 && twi_write(reg) == 0 && twi_write(value) == 0 ? 0 : -1;
    twi_stop();
    return ok;
}

int8_t hw_imu_init(void)
{
    return imu_write(0x6Bu, 0x00u) == 0 && imu_write(0x1Bu, 0x08u) == 0 /* gyro +-500 deg/s */
                   && imu_write(0x1Cu, 0x08u) == 0                      /* accel +-4 g */
               ? 0
               : -1;
}

/* The periodic read runs in the TWI interrupt, so the loop sleeps while the bus works: register
 * pointer 0x3B written, a repeated start, 14 bytes read (accelerometer, temperature, gyro). */
enum imu_step { IMU_IDLE, IMU_START, IMU_ADDRESS_W, IMU_POINTER, IMU_RESTART, IMU_ADDRESS_R, IMU_DATA, IMU_DONE, IMU_FAILED };
static volatile uint8_t imu_step_ = IMU_IDLE;
static volatile uint8_t imu_bytes_[14];
static volatile uint8_t imu_count_;

static void twi_go(uint8_t extra) { TWCR = (uint8_t)((1u << TWINT) | (1u << TWEN) | (1u << TWIE) | extra); }

static void imu_fail(void)
{
    TWCR = (uint8_t)((1u << TWINT) | (1u << TWEN) | (1u << TWSTO));
    imu_step_ = IMU_FAILED;
}

ISR(TWI_vect)
{
    const uint8_t status = TWSR & 0xF8u;
    switch (imu_step_) {
    case IMU_START:
        if (status != 0x08u) { imu_fail(); return; }
        TWDR = (uint8_t)(IMU_ADDRESS << 1);
        imu_step_ = IMU_ADDRESS_W;
        twi_go(0);
        break;
    case IMU_ADDRESS_W:
        if (status != 0x18u) { imu_fail(); return; }
        TWDR = 0x3Bu;
        imu_step_ = IMU_POINTER;
        twi_go(0);
        break;
    case IMU_POINTER:
        if (status != 0x28u) { imu_fail(); return; }
        imu_step_ = IMU_RESTART;
        twi_go(1u << TWSTA);
        break;
    case IMU_RESTART:
        if (status != 0x10u) { imu_fail(); return; }
        TWDR = (uint8_t)((IMU_ADDRESS << 1) | 1u);
        imu_step_ = IMU_ADDRESS_R;
        twi_go(0);
        break;
    case IMU_ADDRESS_R:
        if (status != 0x40u) { imu_fail(); return; }
        imu_count_ = 0;
        imu_step_ = IMU_DATA;
        twi_go(1u << TWEA);
        break;
    case IMU_DATA:
        if (status != 0x50u && status != 0x58u) { imu_fail(); return; }
        imu_bytes_[imu_count_++] = TWDR;
        if (imu_count_ == sizeof imu_bytes_) {
            TWCR = (uint8_t)((1u << TWINT) | (1u << TWEN) | (1u << TWSTO));
            imu_step_ = IMU_DONE;
        } else {
            twi_go(imu_count_ + 1u == sizeof imu_bytes_ ? 0 : (1u << TWEA));  /* NACK the last byte */
        }
        break;
    default:
        TWCR = (uint8_t)((1u << TWINT) | (1u << TWEN));
        break;
    }
}

void hw_imu_start(void)
{
    if (imu_step_ != IMU_IDLE && imu_step_ != IMU_DONE && imu_step_ != IMU_FAILED) {
        /* the last read never finished (a device that stopped answering): give the bus back */
        TWCR = (uint8_t)((1u << TWINT) | (1u << TWEN) | (1u << TWSTO));
    }
    imu_step_ = IMU_START;
    twi_go(1u << TWSTA);
}

int8_t hw_imu_take(int16_t accel[3], int16_t gyro[3])
{
    if (imu_step_ == IMU_FAILED) {
        imu_step_ = IMU_IDLE;
        return -1;
    }
    if (imu_step_ != IMU_DONE) return 0;
    for (uint8_t i = 0; i < 3; ++i) {
        accel[i] = (int16_t)(((uint16_t)imu_bytes_[2 * i] << 8) | imu_bytes_[2 * i + 1]);
        gyro[i] = (int16_t)(((uint16_t)imu_bytes_[8 + 2 * i] << 8) | imu_bytes_[9 + 2 * i]);
    }
    imu_step_ = IMU_IDLE;
    return 1;
}

uint8_t hw_imu_ready(void) { return imu_step_ == IMU_DONE || imu_step_ == IMU_FAILED; }

/* --- the rest ------------------------------------------------------------------------------ */
uint8_t hw_vehicle_id(void) { return eeprom_read_byte(&ee_vehicle_id); }

void hw_idle(uint8_t (*busy)(void))
{
    cli();
    if (!busy()) {
        sleep_enable();
        sei();
        sleep_cpu();
        sleep_disable();
    }
    sei();
}

void hw_init(void)
{
    /* serial: 115200 with U2X (UBRR = F_CPU / 8 / baud - 1, rounded) */
    UBRR0 = (uint16_t)((F_CPU + 4u * BOARD_BAUD) / (8u * BOARD_BAUD) - 1u);
    UCSR0A = (1u << U2X0);
    UCSR0C = (1u << UCSZ01) | (1u << UCSZ00);
    UCSR0B = (1u << RXEN0) | (1u << TXEN0) | (1u << RXCIE0);
    /* Timer0: CTC, /64, 250 counts = 1 ms */
    TCCR0A = (1u << WGM01);
    OCR0A = 249u;
    TCCR0B = (1u << CS01) | (1u << CS00);
    TIMSK0 = (1u << OCIE0A);
    /* Timer1: fast PWM mode 14 (TOP ICR1), /8 = 2 MHz, OC1A non-inverting: the servo */
    DDRB |= (1u << PB5);
    ICR1 = SERVO_TOP;
    OCR1A = 3000u; /* 1500 us, straight */
    TCCR1A = (1u << COM1A1) | (1u << WGM11);
    TCCR1B = (1u << WGM13) | (1u << WGM12) | (1u << CS11);
    /* Timer3: normal mode, /8 = 2 MHz, overflow counted */
    TCCR3A = 0;
    TCCR3B = (1u << CS31);
    TIMSK3 = (1u << TOIE3);
    /* Timer4: fast PWM mode 14 (TOP ICR4 = 999), /1 = 16 kHz, OC4A non-inverting: the motor */
    DDRH |= (1u << PH3);
    ICR4 = MOTOR_TOP;
    OCR4A = 0;
    TCCR4A = (1u << COM4A1) | (1u << WGM41);
    TCCR4B = (1u << WGM43) | (1u << WGM42) | (1u << CS40);
    MOTOR_DIR_DDR |= (1u << MOTOR_INA) | (1u << MOTOR_INB);
    hw_motor(CPM_MOTOR_BRAKE, 0);
    /* odometer: INT4 on the rising edge */
    EICRB = (1u << ISC41) | (1u << ISC40);
    EIMSK = (1u << INT4);
    /* rangers: triggers out, echoes in with pin-change interrupts */
    DDRC |= 0x07u;
    PORTC &= (uint8_t)~0x07u;
    DDRB &= (uint8_t)~0x07u;
    PCMSK0 = 0x07u;
    PCICR = (1u << PCIE0);
    /* ADC: enabled, /128 = 125 kHz */
    ADCSRA = (1u << ADEN) | (1u << ADPS2) | (1u << ADPS1) | (1u << ADPS0);
    /* TWI: 400 kHz = F_CPU / (16 + 2 * TWBR) */
    TWSR = 0;
    TWBR = (uint8_t)((F_CPU / 400000UL - 16u) / 2u);
    set_sleep_mode(SLEEP_MODE_IDLE);
}
