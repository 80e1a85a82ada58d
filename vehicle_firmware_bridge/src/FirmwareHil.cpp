#include <cpm/vehicle/FirmwareHil.hpp>

#include <cpm/ChildProcess.hpp>
#include <cpm/Error.hpp>
#include <cpm/Logging.hpp>

extern "C" {
#include <avr_adc.h>
#include <avr_eeprom.h>
#include <avr_ioport.h>
#include <avr_twi.h>
#include <avr_uart.h>
#include <sim_avr.h>
#include <sim_elf.h>
#include <sim_time.h>
#include <uart_pty.h>
}

// uart_pty's fifo functions are static to its source; the same ones here, to look into them.
DEFINE_FIFO(uint8_t, uart_pty_fifo);

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <elf.h>
#include <fcntl.h>
#include <fstream>
#include <iterator>
#include <pthread.h>
#include <random>
#include <unistd.h>
#include <vector>

namespace cpm::vehicle {
namespace {

constexpr const char* kChip = "atmega2560";
constexpr uint32_t kClockHz = 16'000'000;
constexpr double kNsPerCycle = 1e9 / kClockHz;

// Data-space addresses of the registers the car reads (avr-libc's iom2560.h; I/O registers
// at their I/O address + 0x20).
constexpr uint16_t kPORTA = 0x22, kDDRB = 0x24, kTCCR1A = 0x80, kOCR1A = 0x88, kTCCR4A = 0xA0, kOCR4A = 0xA8,
                   kDDRH = 0x101;
constexpr uint8_t kCOM1A1 = 7, kCOM4A1 = 7;

// The board's scales (firmware/src/board.h).
constexpr double kBatteryDivider = 2.0, kCurrentMvPerA = 500.0, kSoundMPerS = 343.0;
constexpr double kAccelLsbPerG = 8192.0, kGyroLsbPerDps = 65.5, kGravity = 9.81;
constexpr uint8_t kImuAddress = 0x68;
constexpr double kEchoDelayS = 200e-6;  // an HC-SR04 sends its burst before the echo line rises
constexpr double kSampleS = 250e-6;  // how often the motor and servo outputs are read

/// The chip an AVR ELF was built for, from avr-gcc's .note.gnu.avr.deviceinfo; empty when the
/// note is missing. Throws naming the file when it is not an ELF for the AVR.
std::string elf_chip(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error("firmware_hil: " + path + ": " + std::strerror(errno));
    std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    Elf32_Ehdr eh{};
    if (bytes.size() < sizeof eh || std::memcmp(bytes.data(), ELFMAG, SELFMAG) != 0)
        throw Error("firmware_hil: " + path + " is not an ELF file (give the .elf avr-gcc made, not the .hex)");
    std::memcpy(&eh, bytes.data(), sizeof eh);
    if (bytes[EI_CLASS] != ELFCLASS32 || eh.e_machine != EM_AVR)
        throw Error("firmware_hil: " + path + " is not a program for an AVR microcontroller (ELF machine " +
                    std::to_string(eh.e_machine) + ", the AVR's is " + std::to_string(EM_AVR) + ")");
    auto section = [&](size_t i) {
        Elf32_Shdr sh{};
        const size_t at = eh.e_shoff + i * eh.e_shentsize;
        if (at + sizeof sh > bytes.size()) throw Error("firmware_hil: " + path + ": its section table is cut off");
        std::memcpy(&sh, bytes.data() + at, sizeof sh);
        return sh;
    };
    if (eh.e_shstrndx >= eh.e_shnum) return {};
    const auto names = section(eh.e_shstrndx);
    for (size_t i = 0; i < eh.e_shnum; ++i) {
        const auto sh = section(i);
        if (names.sh_offset + sh.sh_name >= bytes.size() || sh.sh_offset + sh.sh_size > bytes.size()) continue;
        if (std::strcmp(bytes.data() + names.sh_offset + sh.sh_name, ".note.gnu.avr.deviceinfo") != 0) continue;
        // Elf32_Nhdr, "AVR\0", then six words (flash, sram, eeprom: start and size), the
        // offset table's length in bytes (its own word included) and its offsets, the first of
        // them the device name's in the string table that follows.
        const char* note = bytes.data() + sh.sh_offset;
        Elf32_Nhdr nh{};
        if (sh.sh_size < sizeof nh + 4 + 8 * 4) return {};
        std::memcpy(&nh, note, sizeof nh);
        const char* desc = note + sizeof nh + ((nh.n_namesz + 3) & ~3u);
        uint32_t table_len = 0, name_offset = 0;
        std::memcpy(&table_len, desc + 6 * 4, 4);
        std::memcpy(&name_offset, desc + 7 * 4, 4);
        const char* strings = desc + 6 * 4 + table_len;
        if (strings + name_offset >= note + sh.sh_size) return {};
        return std::string(strings + name_offset, strnlen(strings + name_offset, size_t(note + sh.sh_size - strings)));
    }
    return {};
}

template <class T>
T saturate(double value)
{
    const double lo = std::numeric_limits<T>::min(), hi = std::numeric_limits<T>::max();
    return static_cast<T>(std::lround(std::clamp(value, lo, hi)));
}

/// Keeps stdout's bytes away while simavr's parts print their banners.
class QuietStdout
{
public:
    QuietStdout()
    {
        std::fflush(stdout);
        saved_ = ::dup(1);
        const int null = ::open("/dev/null", O_WRONLY | O_CLOEXEC);
        if (null >= 0) {
            ::dup2(null, 1);
            ::close(null);
        }
    }
    ~QuietStdout()
    {
        std::fflush(stdout);
        if (saved_ >= 0) {
            ::dup2(saved_, 1);
            ::close(saved_);
        }
    }
    QuietStdout(const QuietStdout&) = delete;
    QuietStdout& operator=(const QuietStdout&) = delete;

private:
    int saved_ = -1;
};

}  // namespace

void check_firmware_elf(const std::string& path)
{
    const std::string chip = elf_chip(path);
    if (!chip.empty() && chip != kChip)
        throw Error("firmware_hil: " + path + " is built for " + chip + "; firmware_hil runs an " + kChip);
}

std::string default_firmware_elf() { return executable_dir() + "/../share/cpm/firmware/cpm_car.elf"; }

struct FirmwareHil::Impl
{
    explicit Impl(FirmwareHilOptions o);
    ~Impl();

    void connect_uart();
    void connect_imu();
    void sample_outputs();
    void step_physics();
    void update_imu();
    void schedule_edges(uint64_t count);
    void on_trigger(uint32_t value);
    void on_chip_byte(uint8_t byte);
    double noise(double sigma) { return sigma > 0 ? std::normal_distribution<double>(0, sigma)(rng) : 0.0; }
    uint64_t cycles_for(double seconds) const { return uint64_t(std::llround(seconds * kClockHz)); }

    static avr_cycle_count_t physics_timer(avr_t*, avr_cycle_count_t when, void* self);
    static avr_cycle_count_t sample_timer(avr_t*, avr_cycle_count_t when, void* self);
    static avr_cycle_count_t edge_timer(avr_t*, avr_cycle_count_t when, void* self);

    /// One ranger's echo line.
    struct Echo
    {
        Impl* hil = nullptr;
        int index = 0;
        uint64_t width = 0;  // cycles
        static avr_cycle_count_t rise(avr_t*, avr_cycle_count_t when, void* self);
        static avr_cycle_count_t fall(avr_t*, avr_cycle_count_t when, void* self);
    };

    FirmwareHilOptions options;
    FirmwareSim sim;
    std::mt19937 rng;
    avr_t* avr = nullptr;
    uart_pty_t pty{};
    bool pty_started = false;
    avr_irq_t* chip_out = nullptr;     // our hook between the chip's UART and the pty
    avr_irq_t* imu_irq = nullptr;
    std::string device;
    std::function<void(uint64_t)> on_state;
    FirmwareHilStats stats;
    FrameDecoder chip_frames;          // what the chip says, decoded to count and check it
    std::vector<uint8_t> out_frame;    // the state frame on its way out (for --corrupt-rate)
    bool last_watchdog = false, last_bad = false;

    uint64_t physics_cycles = 0, steps = 0, steps_per_state = 1;
    double travelled = 0, last_distance = 0;  // |distance| summed, for the hall edges
    uint64_t edges_sent = 0, edges_due = 0, edge_interval = 1;
    bool edge_high = false;
    std::array<Echo, 3> echoes{};

    // The IMU's registers (MPU-6050 map: 0x3B.. accel, temperature, gyro, big-endian).
    std::array<uint8_t, 128> imu{};
    uint8_t imu_pointer = 0;
    bool imu_selected = false, imu_have_pointer = false;

    // The motor and servo as the pins last showed them.
    MotorMode mode = MotorMode::brake;
    uint16_t pwm = 0, servo_us = 1500;
};

void check_firmware_parameters(const VehicleParameters& p)
{
    struct Fixed
    {
        const char* name;
        double given, firmware;
        const char* where;
    };
    const Fixed fixed[] = {{"ticks_per_metre", p.ticks_per_metre, 600, "ODOMETER_TICKS_PER_METRE"},
                           {"ultrasonic_max_range", p.ultrasonic_max_range, 3.0, "RANGER_MAX_MM"},
                           {"ultrasonic_min_range", p.ultrasonic_min_range, 0.02, "RANGER_MIN_MM"},
                           {"state_rate", p.state_rate, 50, "STATE_PERIOD_MS"},
                           {"watchdog_timeout", p.watchdog_timeout, 0.25, "COMMAND_WATCHDOG_MS"}};
    for (const auto& f : fixed) {
        if (std::abs(f.given - f.firmware) > 1e-9 * std::max(1.0, std::abs(f.firmware))) {
            char text[320];
            std::snprintf(text, sizeof text,
                          "firmware_hil: vehicle parameter %s is %g, but the firmware is built for %g (%s in firmware/src/board.h): "
                          "give the car the firmware's value, or build the firmware for yours",
                          f.name, f.given, f.firmware, f.where);
            throw Error(text);
        }
    }
}

FirmwareHil::Impl::Impl(FirmwareHilOptions o)
    : options((check_firmware_parameters(o.parameters), std::move(o))),
      sim(options.parameters, options.world, options.car.start, options.car.vehicle_id, options.car.seed),
      rng(options.car.seed + 7919u)
{
    check_firmware_elf(options.elf);
    {
        QuietStdout quiet;  // simavr tells what it loaded on stdout
        elf_firmware_t firmware{};
        if (elf_read_firmware(options.elf.c_str(), &firmware) != 0)
            throw Error("firmware_hil: simavr could not read " + options.elf);
        avr = avr_make_mcu_by_name(kChip);
        if (avr == nullptr) throw Error(std::string("firmware_hil: this simavr has no ") + kChip + " core");
        avr_init(avr);
        avr->log = 0;
        avr_load_firmware(avr, &firmware);
    }
    avr->frequency = kClockHz;
    avr->vcc = avr->avcc = avr->aref = 5000;
    // The run loop paces the chip; simavr must not sleep on its own when the chip idles.
    avr->sleep = [](avr_t*, avr_cycle_count_t) {};
    uint8_t id = options.car.vehicle_id;
    avr_eeprom_desc_t eeprom{&id, 0, 1};
    avr_ioctl(avr, AVR_IOCTL_EEPROM_SET, &eeprom);

    connect_uart();
    connect_imu();
    avr_irq_register_notify(
        avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('C'), 0),
        [](avr_irq_t*, uint32_t value, void* self) { static_cast<Impl*>(self)->on_trigger(value); }, this);
    for (int i = 0; i < 3; ++i) echoes[size_t(i)] = Echo{this, i, 0};

    const auto& p = options.parameters;
    physics_cycles = cycles_for(1.0 / p.physics_rate);
    steps_per_state = std::max<uint64_t>(1, std::llround(p.physics_rate / p.state_rate));
    update_imu();
    avr_cycle_timer_register(avr, physics_cycles, physics_timer, this);
    avr_cycle_timer_register(avr, cycles_for(kSampleS), sample_timer, this);
}

FirmwareHil::Impl::~Impl()
{
    if (pty_started) {
        // uart_pty_stop would signal its thread with SIGINT; a cancel ends its select() alike
        // without touching the process's signal handling.
        pthread_cancel(pty.thread);
        pthread_join(pty.thread, nullptr);
        for (auto& port : pty.port) {
            if (port.s > 0) ::close(port.s);
        }
    }
    if (!options.car.link.empty()) ::unlink(options.car.link.c_str());
    if (avr != nullptr) avr_terminate(avr);
}

void FirmwareHil::Impl::connect_uart()
{
    {
        QuietStdout quiet;  // uart_pty announces itself on stdout; `device: PATH` must come first
        uart_pty_init(avr, &pty);
        if (pty.pty.s <= 0) throw Error("firmware_hil: simavr's uart_pty could not open a pseudo-terminal");
        pty_started = true;
        uart_pty_connect(&pty, '0');
    }
    device = pty.pty.slavename;
    // uart_pty_connect also points /tmp/simavr-uart0 at the pty: not ours to leave behind.
    char target[256] = {};
    if (::readlink("/tmp/simavr-uart0", target, sizeof target - 1) > 0 && device == target) ::unlink("/tmp/simavr-uart0");
    if (!options.car.link.empty()) {
        ::unlink(options.car.link.c_str());
        if (::symlink(device.c_str(), options.car.link.c_str()) != 0)
            throw Error("firmware_hil: cannot link " + options.car.link + " to " + device + ": " + std::strerror(errno));
    }
    // Between the chip's transmitter and the pty: watch (and, when asked, corrupt) what it says.
    avr_irq_t* tx = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT);
    avr_unconnect_irq(tx, pty.irq + IRQ_UART_PTY_BYTE_IN);
    static const char* names[] = {"8<hil.uart"};
    chip_out = avr_alloc_irq(&avr->irq_pool, 0, 1, names);
    avr_connect_irq(tx, chip_out);
    avr_irq_register_notify(
        chip_out, [](avr_irq_t*, uint32_t value, void* self) { static_cast<Impl*>(self)->on_chip_byte(uint8_t(value)); },
        this);
}

void FirmwareHil::Impl::on_chip_byte(uint8_t byte)
{
    // Frames are held back until their closing zero, so one can be corrupted as a whole.
    out_frame.push_back(byte);
    if (auto packet = chip_frames.push(byte)) {
        if (auto* state = std::get_if<StatePacket>(&*packet)) {
            ++stats.state_packets;
            const bool watchdog = state->status & kStatusWatchdogStop, bad = state->status & kStatusBadCrc;
            stats.watchdog_stops += watchdog && !last_watchdog;
            stats.bad_frames_seen += bad && !last_bad;
            last_watchdog = watchdog;
            last_bad = bad;
        }
    }
    const bool frame_end = byte == 0 && out_frame.size() > 1;
    if (!frame_end && out_frame.size() < 2 * CPM_SERIAL_MAX_WIRE) return;
    if (frame_end && options.corrupt_rate > 0 && std::uniform_real_distribution<double>(0, 1)(rng) < options.corrupt_rate) {
        out_frame[rng() % out_frame.size()] ^= uint8_t(1 + rng() % 255);
        ++stats.corrupted_frames;
    }
    for (uint8_t b : out_frame) avr_raise_irq(pty.irq + IRQ_UART_PTY_BYTE_IN, b);
    // The closing zero opens the next frame too.
    out_frame.clear();
}

void FirmwareHil::Impl::connect_imu()
{
    static const char* names[] = {"8>hil.imu.out", "32<hil.imu.in"};
    imu_irq = avr_alloc_irq(&avr->irq_pool, 0, 2, names);
    avr_connect_irq(avr_io_getirq(avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_OUTPUT), imu_irq + TWI_IRQ_OUTPUT);
    avr_connect_irq(imu_irq + TWI_IRQ_INPUT, avr_io_getirq(avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_INPUT));
    avr_irq_register_notify(
        imu_irq + TWI_IRQ_OUTPUT,
        [](avr_irq_t*, uint32_t value, void* param) {
            // An I2C slave as simavr's parts answer: ACK our address, take a register pointer
            // and register writes, hand out registers from the pointer on reads.
            auto& d = *static_cast<Impl*>(param);
            avr_twi_msg_irq_t v;
            v.u.v = value;
            if (v.u.twi.msg & TWI_COND_STOP) d.imu_selected = false;
            if (v.u.twi.msg & TWI_COND_START) {
                d.imu_selected = (v.u.twi.addr >> 1) == kImuAddress;
                d.imu_have_pointer = false;
                if (d.imu_selected) avr_raise_irq(d.imu_irq + TWI_IRQ_INPUT, avr_twi_irq_msg(TWI_COND_ACK, v.u.twi.addr, 1));
            }
            if (!d.imu_selected) return;
            if (v.u.twi.msg & TWI_COND_WRITE) {
                avr_raise_irq(d.imu_irq + TWI_IRQ_INPUT, avr_twi_irq_msg(TWI_COND_ACK, v.u.twi.addr, 1));
                if (!d.imu_have_pointer) {
                    d.imu_pointer = uint8_t(v.u.twi.data & 0x7F);
                    d.imu_have_pointer = true;
                } else {
                    d.imu[d.imu_pointer] = v.u.twi.data;
                    d.imu_pointer = uint8_t((d.imu_pointer + 1) & 0x7F);
                }
            }
            if (v.u.twi.msg & TWI_COND_READ) {
                avr_raise_irq(d.imu_irq + TWI_IRQ_INPUT, avr_twi_irq_msg(TWI_COND_READ, v.u.twi.addr, d.imu[d.imu_pointer]));
                d.imu_pointer = uint8_t((d.imu_pointer + 1) & 0x7F);
            }
        },
        this);
}

void FirmwareHil::Impl::update_imu()
{
    const auto& m = sim.model();
    const auto& p = options.parameters;
    const double g = kAccelLsbPerG / kGravity;
    const double accel[3] = {(m.acceleration() + noise(p.imu_acceleration_noise)) * g,
                             (m.speed() * m.yaw_rate() + noise(p.imu_acceleration_noise)) * g,
                             (kGravity + noise(p.imu_acceleration_noise)) * g};
    const double gyro_z = (m.yaw_rate() + noise(p.imu_yaw_rate_noise)) * 180.0 / M_PI * kGyroLsbPerDps;
    auto put = [&](size_t reg, double value) {
        const auto word = uint16_t(saturate<int16_t>(value));
        imu[reg] = uint8_t(word >> 8);
        imu[reg + 1] = uint8_t(word);
    };
    for (size_t i = 0; i < 3; ++i) put(0x3B + 2 * i, accel[i]);
    put(0x41, 0);  // temperature
    put(0x43, 0);
    put(0x45, 0);
    put(0x47, gyro_z);
}

void FirmwareHil::Impl::sample_outputs()
{
    const uint8_t* r = avr->data;
    const uint8_t dir = r[kPORTA] & 0x03;
    const bool motor_pin = (r[kDDRH] & (1u << 3)) && (r[kTCCR4A] & (1u << kCOM4A1));
    const bool servo_pin = (r[kDDRB] & (1u << 5)) && (r[kTCCR1A] & (1u << kCOM1A1));
    const uint16_t duty = motor_pin ? uint16_t(r[kOCR4A] | (r[kOCR4A + 1] << 8)) : 0;
    MotorMode new_mode = dir == 0x01 ? MotorMode::forward : dir == 0x02 ? MotorMode::reverse : MotorMode::brake;
    uint16_t new_pwm = new_mode == MotorMode::brake ? 0 : std::min<uint16_t>(duty, 1000);
    uint16_t new_servo = servo_us;
    if (servo_pin) new_servo = uint16_t((r[kOCR1A] | (r[kOCR1A + 1] << 8)) / 2);
    if (new_mode == mode && new_pwm == pwm && new_servo == servo_us) return;
    const bool motor_changed = new_mode != mode || new_pwm != pwm;
    mode = new_mode, pwm = new_pwm, servo_us = new_servo;
    sim.drive(mode, pwm, servo_us);
    if (!motor_changed) return;
    ++stats.motor_changes;
    if (options.trace_pwm) {
        const uint64_t now = uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                          std::chrono::system_clock::now().time_since_epoch())
                                          .count());
        std::printf("pwm %llu %d %u\n", static_cast<unsigned long long>(now), static_cast<int>(mode), unsigned(pwm));
        std::fflush(stdout);
    }
}

void FirmwareHil::Impl::step_physics()
{
    const auto& p = options.parameters;
    sim.step();
    for (const auto& c : sim.take_collisions()) {
        ++stats.wall_collisions;
        CPM_LOG_WARN("%s", describe_collision(options.car.vehicle_id, c).c_str());
    }
    const double distance = sim.model().distance();
    travelled += std::abs(distance - last_distance);
    last_distance = distance;
    const auto ticks = uint64_t(std::floor(travelled * p.ticks_per_metre));
    if (ticks > edges_sent + edges_due) schedule_edges(ticks - edges_sent - edges_due);
    const auto& m = sim.model();
    avr_raise_irq(avr_io_getirq(avr, AVR_IOCTL_ADC_GETIRQ, ADC_IRQ_ADC0),
                  uint32_t(std::lround(m.battery_voltage() * 1000.0 / kBatteryDivider)));
    avr_raise_irq(avr_io_getirq(avr, AVR_IOCTL_ADC_GETIRQ, ADC_IRQ_ADC1),
                  uint32_t(std::lround(std::max(0.0, m.motor_current()) * kCurrentMvPerA)));
    update_imu();
    if (++steps % steps_per_state == 0 && on_state) on_state(uint64_t(double(avr->cycle) * kNsPerCycle));
}

void FirmwareHil::Impl::schedule_edges(uint64_t count)
{
    // The edges of this step spread over the next one, a rising and a falling half each.
    const bool idle = edges_due == 0;
    edges_due += count;
    edge_interval = std::max<uint64_t>(2, physics_cycles / (2 * edges_due));
    if (idle) avr_cycle_timer_register(avr, edge_interval, edge_timer, this);
}

avr_cycle_count_t FirmwareHil::Impl::edge_timer(avr_t* avr, avr_cycle_count_t when, void* self)
{
    auto& d = *static_cast<Impl*>(self);
    d.edge_high = !d.edge_high;
    avr_raise_irq(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('E'), 4), d.edge_high ? 1 : 0);
    if (!d.edge_high) {
        ++d.edges_sent;
        if (--d.edges_due == 0) return 0;
    }
    return when + d.edge_interval;
}

void FirmwareHil::Impl::on_trigger(uint32_t value)
{
    if (value != 0) return;  // the trigger's falling edge starts the measurement
    const auto& p = options.parameters;
    for (auto& echo : echoes) {
        double d = sim.ultrasonic_range(size_t(echo.index));
        if (d < p.ultrasonic_max_range) {
            d = std::clamp(d + noise(p.ultrasonic_noise), p.ultrasonic_min_range, p.ultrasonic_max_range);
        }
        echo.width = cycles_for(2.0 * d / kSoundMPerS);
        avr_cycle_timer_register(avr, cycles_for(kEchoDelayS), Echo::rise, &echo);
    }
}

avr_cycle_count_t FirmwareHil::Impl::Echo::rise(avr_t* avr, avr_cycle_count_t, void* self)
{
    auto& e = *static_cast<Echo*>(self);
    avr_raise_irq(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), uint8_t(e.index)), 1);
    avr_cycle_timer_register(avr, e.width, fall, self);
    return 0;
}

avr_cycle_count_t FirmwareHil::Impl::Echo::fall(avr_t* avr, avr_cycle_count_t, void* self)
{
    auto& e = *static_cast<Echo*>(self);
    avr_raise_irq(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), uint8_t(e.index)), 0);
    return 0;
}

avr_cycle_count_t FirmwareHil::Impl::physics_timer(avr_t*, avr_cycle_count_t when, void* self)
{
    auto& d = *static_cast<Impl*>(self);
    d.sample_outputs();
    d.step_physics();
    return when + d.physics_cycles;
}

avr_cycle_count_t FirmwareHil::Impl::sample_timer(avr_t*, avr_cycle_count_t when, void* self)
{
    auto& d = *static_cast<Impl*>(self);
    d.sample_outputs();
    return when + d.cycles_for(kSampleS);
}

FirmwareHil::FirmwareHil(FirmwareHilOptions options) : impl_(std::make_unique<Impl>(std::move(options))) {}
FirmwareHil::~FirmwareHil() = default;

const std::string& FirmwareHil::device() const { return impl_->device; }
uint64_t FirmwareHil::chip_ns() const { return uint64_t(double(impl_->avr->cycle) * kNsPerCycle); }

void FirmwareHil::run_to(uint64_t t)
{
    auto& d = *impl_;
    const auto target = avr_cycle_count_t(double(t) / kNsPerCycle);
    const auto started = std::chrono::steady_clock::now();
    while (d.avr->cycle < target) {
        const int state = avr_run(d.avr);
        if (state == cpu_Done || state == cpu_Crashed) {
            char where[64];
            std::snprintf(where, sizeof where, " at %.6f s (pc 0x%x)", double(d.avr->cycle) * kNsPerCycle * 1e-9, unsigned(d.avr->pc));
            throw Error(std::string("firmware_hil: the chip ") + (state == cpu_Crashed ? "crashed" : "stopped") + where);
        }
    }
    d.stats.wall_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
}

bool FirmwareHil::frame_waiting() const
{
    // The host's bytes wait in uart_pty's fifo until the chip's receiver takes them: a zero
    // after at least one other byte closes a frame.
    auto& fifo = impl_->pty.pty.out;
    const auto n = uart_pty_fifo_get_read_size(&fifo);
    bool body = false;
    for (uint16_t i = 0; i < n; ++i) {
        const uint8_t b = uart_pty_fifo_read_at(&fifo, i);
        if (b != 0) {
            body = true;
        } else if (body) {
            return true;
        }
    }
    return false;
}

bool FirmwareHil::output_pending() const
{
    return !impl_->out_frame.empty() || !uart_pty_fifo_isempty(&impl_->pty.pty.in);
}

void FirmwareHil::on_state_period(std::function<void(uint64_t)> callback) { impl_->on_state = std::move(callback); }
FirmwareSim& FirmwareHil::car() { return impl_->sim; }

FirmwareHilStats FirmwareHil::stats() const
{
    auto s = impl_->stats;
    s.cycles = impl_->avr->cycle;
    return s;
}

void FirmwareHil::note_lag(double ms) { impl_->stats.lag_max_ms = std::max(impl_->stats.lag_max_ms, ms); }

}  // namespace cpm::vehicle
