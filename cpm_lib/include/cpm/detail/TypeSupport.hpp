#pragma once
#include <algorithm>
#include <cstdint>
#include <cstring>
#include <memory>
#include <type_traits>
#include <utility>

#include <cpm/TopicType.hpp>
#include <cpm_topic_types.hpp>

namespace eprosima::fastdds::dds {
class TopicDataType;
}

namespace cpm::detail {

/// Creates a new instance of a type's DDS type support; the caller owns it.
using MakeTypeSupport = eprosima::fastdds::dds::TopicDataType* (*)();

template <class T>
eprosima::fastdds::dds::TopicDataType* make_type_support()
{
    return TopicType<T>::make_type_support();
}

/// Fast DDS 2.9 lays a lent sample of a plain type 4 bytes past an 8-byte boundary in data
/// sharing's pool (after the payload's 4-byte encapsulation header): types aligned to at most this
/// are read and written there in place; a type with 8-byte fields (alignof 8) is not.
inline constexpr size_t kLentSampleAlignment = 4;

template <class T>
bool aligned_for(const void* lent)
{
    return reinterpret_cast<std::uintptr_t>(lent) % alignof(T) == 0;
}

/// Calls use(T&) with a sample Fast DDS lent (a reader's take). Where the loan is not aligned for
/// T (a plain type with 8-byte fields in data sharing's pool) binding a T& to it would be undefined
/// behaviour: use gets an aligned copy of the sample's bytes instead (a plain type is its bytes).
template <class T, class Use>
void with_lent(void* lent, Use&& use)
{
    if (aligned_for<T>(lent)) {
        use(*static_cast<T*>(lent));
        return;
    }
    auto copy = std::make_unique<T>();
    // The bytes Fast DDS holds of a plain sample: its serialized size (without tail padding).
    const size_t bytes = std::min(sizeof(T), static_cast<size_t>(T::getMaxCdrSerializedSize()));
    std::memcpy(static_cast<void*>(copy.get()), lent, bytes);
    use(*copy);
}

template <class T, class = void>
struct HasVehicleId : std::false_type {};
template <class T>
struct HasVehicleId<T, std::void_t<decltype(std::declval<const T&>().vehicle_id())>> : std::true_type {};

template <class T, class = void>
struct HasHeader : std::false_type {};
template <class T>
struct HasHeader<T, std::void_t<decltype(std::declval<const T&>().header().create_stamp().nanoseconds())>>
    : std::true_type {};

template <class T>
uint64_t create_stamp_of(const T& s) { return s.header().create_stamp().nanoseconds(); }
template <class T>
uint64_t valid_after_stamp_of(const T& s) { return s.header().valid_after_stamp().nanoseconds(); }

}  // namespace cpm::detail
