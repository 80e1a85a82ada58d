#pragma once
#include <cstdint>

namespace cpm {

/// Stamps a message whose first member is `Header header`: create_stamp = t_now_ns,
/// valid_after_stamp = t_now_ns + expected_delay_ns (when readers may use it).
template <class T>
void stamp_message(T& message, uint64_t t_now_ns, uint64_t expected_delay_ns)
{
    message.header().create_stamp().nanoseconds(t_now_ns);
    message.header().valid_after_stamp().nanoseconds(t_now_ns + expected_delay_ns);
}

}  // namespace cpm
