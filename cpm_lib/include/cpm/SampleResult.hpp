#pragma once
#include <cstdint>

namespace cpm {

/// What Reader<T>::get_sample returns.
template <class T>
struct SampleResult
{
    T sample{};          ///< the newest valid sample (default-constructed when !valid)
    uint64_t age_ns = 0; ///< t_now - valid_after_stamp of that sample
    bool valid = false;  ///< false when no buffered sample is valid at t_now
};

}  // namespace cpm
