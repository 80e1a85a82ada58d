#include <cpm/init.hpp>
#include <cpm_test/Dds.hpp>

#include <cpm_test/Isolation.hpp>

namespace cpm_test {

cpm::ParticipantOptions isolated_options()
{
    cpm::ParticipantOptions options;
    options.domain_id = test_domain_id();
    options.name = "cpm_test";
    options.shared_memory = cpm::init_settings().shared_memory;  // CPM_SHARED_MEMORY=off: UDP loopback only
    return options;
}

VehicleState vehicle_state(uint8_t vehicle_id, uint64_t create_ns, uint64_t valid_after_ns, double tag)
{
    VehicleState s;
    s.vehicle_id(vehicle_id);
    s.header().create_stamp().nanoseconds(create_ns);
    s.header().valid_after_stamp().nanoseconds(valid_after_ns);
    s.pose().x(tag);
    return s;
}

}  // namespace cpm_test
