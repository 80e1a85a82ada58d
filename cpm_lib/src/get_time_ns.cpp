#include <cpm/get_time_ns.hpp>

#include <ctime>

namespace cpm {

uint64_t get_time_ns()
{
    timespec ts{};
    clock_gettime(CLOCK_REALTIME, &ts);
    return static_cast<uint64_t>(ts.tv_sec) * 1'000'000'000ull + static_cast<uint64_t>(ts.tv_nsec);
}

}  // namespace cpm
