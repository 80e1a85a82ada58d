#pragma once

namespace cpm {

/// Maps a message type to its DDS type support (the fastddsgen-generated `TPubSubType`).
/// Specialised for every lab type in <cpm_topic_types.hpp>; for a type of your own
/// generated with fastddsgen, write CPM_REGISTER_TYPE(MyType) at global scope.
template <class T>
struct TopicType;

}  // namespace cpm

/// Registers a global-namespace type T whose type support class is T##PubSubType.
#define CPM_REGISTER_TYPE(T) CPM_REGISTER_TYPE_AS(T, T##PubSubType)

/// Registers type T (fully qualified) with the type support class PubSub.
#define CPM_REGISTER_TYPE_AS(T, PubSub)      \
    namespace cpm {                          \
    template <>                              \
    struct TopicType<T>                      \
    {                                        \
        using PubSubType = PubSub;           \
    };                                       \
    }
