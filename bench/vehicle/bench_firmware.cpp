// The car's real firmware under firmware_hil, measured:
//  1. speed: one simulated ATmega2560 running as fast as it can, idle (no host) and driving (a
//     host end answering every state packet with a command, as the bridge does): simulated MHz
//     and real-time factor on one core;
//  2. capacity: chips spread over two threads (two cores), as fast as they run: how many cars'
//     chips this machine carries at real time, with a margin of 1.5x;
//  3. command latency: a command frame written to the pty -> the motor output changed, with
//     firmware_hil (the chip's PWM register) and with firmware_sim (its held command), both
//     --trace-pwm, in alternating blocks of the same run;
//  4. flash and RAM of the ELF against the chip's 256 KiB / 8 KiB and the firmware's budget.
//
//   bench_firmware [--seconds 20] [--chips 8] [--commands 100]
#include "bench_common.hpp"

#include <cpm/ChildProcess.hpp>
#include <cpm/CommandLine.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/vehicle/FirmwareHil.hpp>
#include <cpm/vehicle/Protocol.hpp>
#include <cpm/vehicle/SerialPort.hpp>

#include <nlohmann/json.hpp>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <memory>
#include <sstream>
#include <thread>
#include <unistd.h>
#include <variant>

namespace {

using namespace std::chrono_literals;
constexpr uint64_t kSlice = 20'000'000;  // chip time per step of the loops here: one state period

/// The tick of the newest state packet waiting on `port` (read without waiting), or `newest`.
uint32_t newest_state_tick(cpm::vehicle::SerialPort& port, cpm::vehicle::FrameDecoder& decoder, uint32_t newest)
{
    uint8_t buffer[512];
    for (long n; (n = port.read_some(buffer, sizeof buffer, 0)) > 0;) {
        for (long i = 0; i < n; ++i) {
            if (auto p = decoder.push(buffer[i])) {
                if (auto* s = std::get_if<cpm::vehicle::StatePacket>(&*p)) newest = s->tick;
            }
        }
    }
    return newest;
}

/// The host's end of one chip's line: answers every state packet with a forward command (a
/// command names the state it answers; the firmware ignores one answering an old state).
class HostEnd
{
public:
    HostEnd(const std::string& device, uint8_t id) : port_(device, 115200), id_(id) {}
    void answer()
    {
        const uint32_t newest = newest_state_tick(port_, decoder_, answered_);
        if (newest == answered_) return;
        answered_ = newest;
        cpm::vehicle::CommandPacket c{newest, id_, cpm::vehicle::MotorMode::forward, 300, 1600};
        auto frame = cpm::vehicle::encode_frame(c);
        (void)port_.write_all(frame.data(), frame.size());
    }

private:
    cpm::vehicle::SerialPort port_;
    cpm::vehicle::FrameDecoder decoder_;
    uint8_t id_;
    uint32_t answered_ = 0;
};

cpm::vehicle::FirmwareHilOptions chip_options(uint8_t id)
{
    cpm::vehicle::FirmwareHilOptions o;
    o.elf = cpm::vehicle::default_firmware_elf();
    o.car.vehicle_id = id;
    o.car.seed = id;
    return o;
}

/// Chip seconds per wall second of one chip run for `seconds` of chip time.
double chip_speed(double seconds, bool driving)
{
    cpm::vehicle::FirmwareHil chip(chip_options(1));
    std::unique_ptr<HostEnd> host = driving ? std::make_unique<HostEnd>(chip.device(), 1) : nullptr;
    const auto t0 = std::chrono::steady_clock::now();
    for (uint64_t t = kSlice; t <= uint64_t(seconds * 1e9); t += kSlice) {
        chip.run_to(t);
        if (host) {
            // The pty hands bytes over on uart_pty's thread: give it the moment a real line takes.
            while (chip.output_pending()) std::this_thread::sleep_for(50us);
            host->answer();
        }
    }
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const auto s = chip.stats();
    std::printf("  %-28s %6.1f chip s in %6.2f s: %7.1f simulated MHz, %6.1fx real time; %llu state packets, %llu motor changes\n",
                driving ? "one chip, driving" : "one chip, idle (no host)", seconds, wall, double(s.cycles) / wall * 1e-6,
                seconds / wall, static_cast<unsigned long long>(s.state_packets), static_cast<unsigned long long>(s.motor_changes));
    return seconds / wall;
}

/// Chip seconds per wall second of `chips` chips on two threads, each chip driven by a host end.
/// The chips are made on this thread (simavr's loading and uart_pty's banner are not for two
/// threads at once), then each thread runs its half.
double capacity(int chips, double seconds)
{
    std::vector<std::unique_ptr<cpm::vehicle::FirmwareHil>> all;
    std::vector<std::unique_ptr<HostEnd>> hosts;
    for (int k = 0; k < chips; ++k) {
        all.push_back(std::make_unique<cpm::vehicle::FirmwareHil>(chip_options(uint8_t(1 + k))));
        hosts.push_back(std::make_unique<HostEnd>(all.back()->device(), uint8_t(1 + k)));
    }
    auto worker = [&](size_t begin, size_t end) {
        for (uint64_t t = kSlice; t <= uint64_t(seconds * 1e9); t += kSlice) {
            for (size_t k = begin; k < end; ++k) {
                all[k]->run_to(t);
                hosts[k]->answer();
            }
        }
    };
    const auto t0 = std::chrono::steady_clock::now();
    std::thread a(worker, 0, size_t(chips / 2)), b(worker, size_t(chips / 2), size_t(chips));
    a.join();
    b.join();
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const double rate = seconds * chips / wall;
    std::printf("  %d chips on two threads: %.1f chip s in %.2f s = %.1f chip seconds per second\n", chips, seconds * chips, wall, rate);
    return rate;
}

/// N firmware_hil processes in real time for `seconds`, each with a host end answering its
/// state packets as the bridge does (from this process: one thread for all lines); returns the
/// worst lag behind the wall clock of any chip (ms) and prints the missed ticks and CPU.
double processes(int n, int seconds)
{
    std::vector<cpm::ChildProcess> children;
    std::vector<std::string> outs;
    for (int k = 0; k < n; ++k) {
        outs.push_back("/tmp/bench_firmware_" + std::to_string(::getpid()) + "_p" + std::to_string(k) + ".out");
        children.push_back(bench::spawn({cpm::sibling_executable("firmware_hil"), "--vehicle_id", std::to_string(k + 1)},
                                        {"CPM_DOMAIN_ID=212"}, outs.back()));
    }
    std::vector<std::unique_ptr<HostEnd>> hosts;
    for (int k = 0; k < n; ++k) {
        for (int i = 0; i < 200; ++i) {
            std::ifstream in(outs[size_t(k)]);
            std::string line;
            if (std::getline(in, line) && line.rfind("device: ", 0) == 0) {
                hosts.push_back(std::make_unique<HostEnd>(line.substr(8), uint8_t(k + 1)));
                break;
            }
            std::this_thread::sleep_for(20ms);
        }
    }
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(seconds);
    while (std::chrono::steady_clock::now() < until) {
        for (auto& h : hosts) h->answer();
        std::this_thread::sleep_for(2ms);
    }
    for (auto& c : children) c.signal(SIGTERM);
    double worst = 0, missed = 0, packets = 0;
    for (size_t k = 0; k < children.size(); ++k) {
        (void)bench::wait_child(children[k], 10);
        std::ifstream in(outs[k]);
        std::string last;
        for (std::string line; std::getline(in, line);) {
            if (!line.empty() && line[0] == '{') last = line;
        }
        ::unlink(outs[k].c_str());
        if (last.empty()) continue;
        const auto j = nlohmann::json::parse(last);
        worst = std::max(worst, j["lag_max_ms"].get<double>());
        missed += j["missed_ticks"].get<double>();
        packets += j["state_packets"].get<double>();
    }
    std::printf("  %2d processes: worst lag %6.1f ms, missed ticks %5.2f %% (of 500/s each), state packets %.0f of %d expected\n", n, worst,
                missed / (n * seconds * 500.0) * 100, packets, n * seconds * 50);
    return worst;
}

/// Command latency (us) of `program` (firmware_hil or firmware_sim): frames alternating PWM 300
/// and 400 every 50 ms, matched to its --trace-pwm lines.
std::vector<double> command_latency(const std::string& program, int commands)
{
    const std::string out = "/tmp/bench_firmware_" + std::to_string(::getpid()) + "_" + program + ".out";
    auto child = bench::spawn({cpm::sibling_executable(program), "--vehicle_id", "7", "--trace-pwm", "--realtime"},
                              {"CPM_DOMAIN_ID=211"}, out);
    std::string device;
    for (int i = 0; i < 200 && device.empty(); ++i) {
        std::this_thread::sleep_for(20ms);
        std::ifstream in(out);
        std::string line;
        if (std::getline(in, line) && line.rfind("device: ", 0) == 0) device = line.substr(8);
    }
    if (device.empty()) throw cpm::Error("bench_firmware: " + program + " named no device");
    std::vector<std::pair<uint64_t, uint16_t>> written;
    {
        cpm::vehicle::SerialPort port(device, 115200);
        cpm::vehicle::FrameDecoder decoder;
        uint32_t newest = 0;
        for (int i = 0; i < 100 && newest == 0; ++i) {
            std::this_thread::sleep_for(10ms);
            newest = newest_state_tick(port, decoder, newest);
        }
        if (newest == 0) throw cpm::Error("bench_firmware: " + program + " sent no state packet within 1 s");
        for (int i = 0; i < commands; ++i) {
            const uint16_t pwm = i % 2 ? 400 : 300;
            newest = newest_state_tick(port, decoder, newest);  // each command answers the newest state
            cpm::vehicle::CommandPacket c{newest, 7, cpm::vehicle::MotorMode::forward, pwm, 1500};
            auto frame = cpm::vehicle::encode_frame(c);
            written.emplace_back(cpm::get_time_ns(), pwm);
            (void)port.write_all(frame.data(), frame.size());
            std::this_thread::sleep_for(50ms);
        }
        std::this_thread::sleep_for(100ms);
    }
    child.signal(SIGTERM);
    (void)bench::wait_child(child, 10);
    std::vector<std::pair<uint64_t, uint16_t>> traced;
    std::ifstream in(out);
    for (std::string word; in >> word;) {
        if (word != "pwm") continue;
        unsigned long long t = 0;
        int mode = 0;
        unsigned pwm = 0;
        if (in >> t >> mode >> pwm) traced.emplace_back(t, uint16_t(pwm));
    }
    ::unlink(out.c_str());
    std::vector<double> latencies;
    size_t j = 0;
    for (const auto& [t, pwm] : written) {
        while (j < traced.size() && traced[j].first < t) ++j;
        if (j < traced.size() && traced[j].second == pwm && traced[j].first - t < 50'000'000) latencies.push_back(double(traced[j].first - t) * 1e-3);
    }
    return latencies;
}

void flash_and_ram()
{
    const std::string elf = cpm::vehicle::default_firmware_elf();
    FILE* p = ::popen(("avr-size -A '" + elf + "'").c_str(), "r");
    if (p == nullptr) return;
    unsigned long text = 0, data = 0, bss = 0;
    char line[256];
    while (std::fgets(line, sizeof line, p)) {
        char name[64];
        unsigned long size = 0;
        if (std::sscanf(line, "%63s %lu", name, &size) != 2) continue;
        if (std::string(name) == ".text") text = size;
        if (std::string(name) == ".data") data = size;
        if (std::string(name) == ".bss") bss = size;
    }
    ::pclose(p);
    const double flash = double(text + data), ram = double(data + bss);
    std::printf("  flash %.0f B = %.1f %% of 256 KiB (budget 32768 B); RAM %.0f B = %.1f %% of 8 KiB (budget 2048 B; the rest is stack)\n", flash,
                flash / 2621.44, ram, ram / 81.92);
    bench::record({"firmware", "flash (.text + .data)", "B", flash, "the ATmega2560's flash", 262144, "<= 32768 B (the budget)", flash <= 32768});
    bench::record({"firmware", "RAM (.data + .bss)", "B", ram, "the ATmega2560's SRAM", 8192, "<= 2048 B (the budget)", ram <= 2048});
}

const char* kHelp =
    "usage: bench_firmware [--seconds S] [--chips N] [--commands N]\n"
    "\n"
    "The car's AVR firmware under firmware_hil: simulated MHz and real-time factor of one chip\n"
    "(idle and driving), how many chips two cores carry at real time, the command latency from a\n"
    "frame written to the pty to the motor output against firmware_sim's, and flash/RAM use.\n"
    "  --seconds S    chip time per speed case (default 20)\n"
    "  --chips N      chips in the capacity case, on two threads (default 8)\n"
    "  --commands N   commands per latency block (default 100; two blocks per program)\n";

int run(int argc, char** argv)
{
    const auto flags = cpm::cli::parse_flags(argc, argv, {{"--seconds", true}, {"--chips", true}, {"--commands", true}}, "bench_firmware");
    const double seconds = cpm::cli::parse_number("--seconds", flags.get("--seconds", "20"), 1, 3600);
    const int chips = int(cpm::cli::parse_integer("--chips", flags.get("--chips", "8"), 2, 64));
    const int commands = int(cpm::cli::parse_integer("--commands", flags.get("--commands", "100"), 10, 10000));
    bench::print_machine("ATmega2560 at 16 MHz in simavr; " + std::to_string(int(seconds)) + " chip seconds per speed case");

    std::printf("\n1. speed of one chip (one core)\n");
    (void)chip_speed(seconds, false);
    const double one = chip_speed(seconds, true);
    bench::record({"firmware", "one chip driving, real-time factor", "x", one, "", 0, ">= 1.5x (real time with margin)", one >= 1.5});

    std::printf("\n2. capacity: chips on two threads, each answered as the bridge does\n");
    const double carried = capacity(chips, seconds / 2);
    const int fit = int(carried / 1.5);
    std::printf("  -> about %d cars' chips at real time with a 1.5x margin, counting the simulation alone\n", fit);
    bench::record({"firmware", "chips on two threads in one process at 1.5x margin", "cars", double(fit), "", 0, "", -1});

    std::printf("\n   the same as real processes (firmware_hil in real time, its lines answered): a size fits\n"
                "   while no chip lags a state period (20 ms) behind the wall clock\n");
    int fits = 0;
    for (int n : {4, 8, 12, 16}) {
        if (processes(n, int(seconds / 2)) >= 20.0) break;
        fits = n;
    }
    std::printf("  -> %d firmware_hil processes keep real time on this machine\n", fits);
    bench::record({"firmware", "firmware_hil processes in real time on two cores (lag < 20 ms)", "cars", double(fits), "", 0, "", -1});

    std::printf("\n3. command latency: frame written to the pty -> motor output changed (us)\n");
    bench::print_header("program");
    std::vector<double> hil, sim;
    for (int block = 0; block < 2; ++block) {
        auto s = command_latency("firmware_sim", commands);
        sim.insert(sim.end(), s.begin(), s.end());
        auto h = command_latency("firmware_hil", commands);
        hil.insert(hil.end(), h.begin(), h.end());
    }
    const auto hs = bench::stats_of(hil), ss = bench::stats_of(sim);
    bench::print_row("firmware_hil (AVR)", hs);
    bench::print_row("firmware_sim", ss);
    bench::print_ratio("AVR / firmware_sim", hs, ss);
    std::printf("  matched %zu of %d commands (AVR), %zu of %d (firmware_sim)\n", hil.size(), 2 * commands, sim.size(), 2 * commands);
    bench::record_latency("firmware", "command write -> motor output", hs, "firmware_sim (--trace-pwm)", ss);

    std::printf("\n4. flash and RAM of the firmware\n");
    flash_and_ram();
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "bench_firmware", kHelp, run); }
