#pragma once
#include <cpm/Participant.hpp>

#include <VehicleState.h>

#include <cstdint>

namespace cpm_test {

/// Options for a participant on this test process's own domain (loopback + shared memory).
cpm::ParticipantOptions isolated_options();

/// A VehicleState with the given stamps; pose.x carries `tag` so tests can tell samples apart.
VehicleState vehicle_state(uint8_t vehicle_id, uint64_t create_ns, uint64_t valid_after_ns, double tag = 0);

}  // namespace cpm_test
