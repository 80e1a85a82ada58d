#pragma once
#include <memory>
#include <utility>

#include <cpm/SampleResult.hpp>
#include <cpm/detail/SampleSelector.hpp>
#include <cpm/detail/TypeSupport.hpp>

namespace cpm::detail {

/// Buffers a stamped sample in a SampleSelector.
template <class T>
void add_sample(SampleSelector& selector, T&& sample)
{
    const uint64_t create = create_stamp_of(sample);
    const uint64_t valid_after = valid_after_stamp_of(sample);
    selector.add(create, valid_after, std::make_shared<const T>(std::move(sample)));
}

/// Reader's rule applied to one selector: the newest valid sample at t_now and its age.
template <class T>
SampleResult<T> select_sample(SampleSelector& selector, uint64_t t_now)
{
    SampleResult<T> result;
    auto pick = selector.select(t_now);
    if (pick.sample) {
        result.sample = *std::static_pointer_cast<const T>(pick.sample);
        result.age_ns = t_now - pick.valid_after_ns;
        result.valid = true;
    }
    return result;
}

}  // namespace cpm::detail
