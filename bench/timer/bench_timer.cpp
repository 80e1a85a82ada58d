// Tick jitter (actual - nominal) of cpm::Timer at 50 Hz and 1 kHz, idle and with the other
// core busy, side by side with a plain clock_nanosleep(TIMER_ABSTIME) loop as reference.
//
//   bench_timer [--seconds 10] [--domain 202]
#include "bench_common.hpp"

#include <cpm/Timer.hpp>
#include <cpm/get_time_ns.hpp>

#include <atomic>
#include <csignal>
#include <cstdio>
#include <ctime>
#include <string>
#include <thread>

#include <unistd.h>

namespace {

std::vector<double> jitter_cpm(cpm::Participant& participant, uint64_t period_ns, int seconds)
{
    std::vector<double> jitter_us;
    const size_t ticks = static_cast<size_t>(uint64_t(seconds) * 1'000'000'000ull / period_ns);
    jitter_us.reserve(ticks);
    auto timer = cpm::Timer::create(participant, "bench_timer", period_ns, 0, false, false);
    timer->start([&](uint64_t nominal) {
        jitter_us.push_back(double(cpm::get_time_ns() - nominal) * 1e-3);
        if (jitter_us.size() >= ticks) timer->stop();
    });
    return jitter_us;
}

std::vector<double> jitter_nanosleep(uint64_t period_ns, int seconds)
{
    std::vector<double> jitter_us;
    const size_t ticks = static_cast<size_t>(uint64_t(seconds) * 1'000'000'000ull / period_ns);
    jitter_us.reserve(ticks);
    uint64_t next = (cpm::get_time_ns() / period_ns + 1) * period_ns;
    while (jitter_us.size() < ticks) {
        timespec ts{static_cast<time_t>(next / 1'000'000'000ull), static_cast<long>(next % 1'000'000'000ull)};
        clock_nanosleep(CLOCK_REALTIME, TIMER_ABSTIME, &ts, nullptr);
        jitter_us.push_back(double(cpm::get_time_ns() - next) * 1e-3);
        next += period_ns;
    }
    return jitter_us;
}

}  // namespace

int main(int argc, char** argv)
{
    if (argc > 1 && std::string(argv[1]) == "--help") {
        std::puts("usage: bench_timer [--seconds 10] [--domain 202]");
        return 0;
    }
    if (bench::arg(argc, argv, "--role", "") == "busy") {
        for (;;) asm volatile("" ::: "memory");  // spin: keep a core busy
    }
    const int seconds = std::stoi(bench::arg(argc, argv, "--seconds", "10"));
    cpm::ParticipantOptions options;
    options.domain_id = std::stoi(bench::arg(argc, argv, "--domain", "202"));
    cpm::Participant participant(options);

    bench::print_machine("jitter = actual - nominal tick time in microseconds; " + std::to_string(seconds) +
                         " s per case; 'busy' = a spinning process competing for the cores; reference: "
                         "clock_nanosleep(CLOCK_REALTIME, TIMER_ABSTIME) loop");
    for (const bool busy : {false, true}) {
        const int spinner = busy ? bench::spawn_self({"--role", "busy"}) : -1;
        for (const uint64_t period : {20'000'000ull, 1'000'000ull}) {
            const std::string rate = period == 20'000'000ull ? "50 Hz" : "1 kHz";
            bench::print_header("tick jitter, " + rate + (busy ? ", other core busy" : ", idle"));
            const auto cpm_stats = bench::stats_of(jitter_cpm(participant, period, seconds));
            const auto ref_stats = bench::stats_of(jitter_nanosleep(period, seconds));
            bench::print_row("cpm::Timer", cpm_stats);
            bench::print_row("clock_nanosleep loop (reference)", ref_stats);
            bench::print_ratio("cpm / reference", cpm_stats, ref_stats);
        }
        if (spinner > 0) {
            kill(spinner, SIGKILL);
            bench::wait_child(spinner, 5);
        }
    }
    std::puts("\nsimulated-clock speed-up: not measured (the simulated clock is not built yet)");
    return 0;
}
