#pragma once
#include <cpm/Participant.hpp>
#include <cpm/ReaderOptions.hpp>
#include <cpm/WriterOptions.hpp>

#include <VehicleState.h>

#include <cstdint>

namespace cpm_test {

/// One millisecond and a plausible lab time, in nanoseconds, for stamps in tests.
inline constexpr uint64_t kMs = 1'000'000;
inline constexpr uint64_t kT0 = 1'700'000'000'000'000'000ull;

/// Reliable keep-last-100 options, for tests that must not lose a sample.
inline const cpm::WriterOptions kReliable{.reliable = true, .keep_all = false, .history_depth = 100};
inline const cpm::ReaderOptions kReliableReader{.reliable = true, .keep_all = false, .history_depth = 100};

/// Options for a participant on this test process's own domain (loopback + shared memory).
cpm::ParticipantOptions isolated_options();

/// A VehicleState with the given stamps; pose.x carries `tag` so tests can tell samples apart.
VehicleState vehicle_state(uint8_t vehicle_id, uint64_t create_ns, uint64_t valid_after_ns, double tag = 0);

}  // namespace cpm_test
