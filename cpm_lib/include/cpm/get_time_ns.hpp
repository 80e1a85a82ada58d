#pragma once
#include <cstdint>

namespace cpm {

/// The lab's current time in nanoseconds: since the Unix epoch (CLOCK_REALTIME), or, in a
/// process started with --simulated_time, the lab's simulated clock (ns since the simulation
/// start, as the last SystemTrigger set it). Thread-safe; costs a few tens of nanoseconds.
uint64_t get_time_ns();

}  // namespace cpm
