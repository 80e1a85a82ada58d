#pragma once
#include <cstdint>
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
