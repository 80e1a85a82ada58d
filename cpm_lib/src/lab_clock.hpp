#pragma once
#include <cstdint>

namespace cpm::detail {

/// Makes cpm::get_time_ns() return the lab's simulated clock (set by cpm::init's
/// --simulated_time) instead of CLOCK_REALTIME.
void use_simulated_clock(bool simulated);
/// The lab clock as the last SystemTrigger set it (simulated time only).
void set_simulated_now(uint64_t t_ns);

}  // namespace cpm::detail
