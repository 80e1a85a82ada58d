#include <cpm/get_time_ns.hpp>

#include "lab_clock.hpp"

#include <atomic>
#include <ctime>

namespace cpm {

namespace {
std::atomic<bool> g_simulated{false};
std::atomic<uint64_t> g_simulated_now{0};
}  // namespace

uint64_t get_time_ns()
{
    if (g_simulated.load(std::memory_order_relaxed)) return g_simulated_now.load(std::memory_order_acquire);
    timespec ts{};
    clock_gettime(CLOCK_REALTIME, &ts);
    return static_cast<uint64_t>(ts.tv_sec) * 1'000'000'000ull + static_cast<uint64_t>(ts.tv_nsec);
}

namespace detail {

void use_simulated_clock(bool simulated) { g_simulated.store(simulated, std::memory_order_relaxed); }

void set_simulated_now(uint64_t t_ns) { g_simulated_now.store(t_ns, std::memory_order_release); }

}  // namespace detail
}  // namespace cpm
