#pragma once
#include <cstddef>
#include <cstdint>
#include <exception>
#include <memory>
#include <mutex>
#include <vector>

namespace eprosima::fastdds::dds {
class TopicDataType;
}

namespace cpm {

/// What cpm needs to know of a message type T, without the user's code reading a Fast DDS
/// header: a specialisation provides
///   static eprosima::fastdds::dds::TopicDataType* make_type_support();  // new, caller owns
///   static bool decode(const std::vector<uint8_t>& cdr, T& out);         // encapsulation included
/// Every lab type is declared in <cpm_topic_types.hpp> and defined in the compiled cpm::idl.
/// For a type of your own generated with fastddsgen, write CPM_REGISTER_TYPE(MyType) at global
/// scope in a file that includes its MyTypePubSubTypes.h.
template <class T>
struct TopicType;

}  // namespace cpm

/// Declares TopicType<T>; CPM_DEFINE_TYPE_AS defines it in one compiled file.
#define CPM_DECLARE_TYPE(T)                                                                        \
    namespace cpm {                                                                                \
    template <>                                                                                    \
    struct TopicType<T>                                                                            \
    {                                                                                              \
        static ::eprosima::fastdds::dds::TopicDataType* make_type_support();                       \
        static bool decode(const std::vector<uint8_t>& cdr, T& out);                              \
    };                                                                                             \
    }

/// The definitions for a declared type T whose type support class is PubSub (needs PubSub's
/// header, and with it Fast DDS's).
#define CPM_DEFINE_TYPE_AS(T, PubSub) CPM_TYPE_DEFINITIONS_(, T, PubSub)

/// Registers a global-namespace type T whose type support class is T##PubSubType.
#define CPM_REGISTER_TYPE(T) CPM_REGISTER_TYPE_AS(T, T##PubSubType)

/// Registers type T (fully qualified) with the type support class PubSub, declared and defined
/// at once (inline): for a file that includes PubSub's header.
#define CPM_REGISTER_TYPE_AS(T, PubSub) CPM_DECLARE_TYPE(T) CPM_TYPE_DEFINITIONS_(inline, T, PubSub)

// The type support cpm hands to Fast DDS is the generated one with two changes:
// - bytes that do not decode are a sample dropped, never an exception. fastddsgen's deserialize()
//   catches only a cut-off buffer; a wrong encapsulation or an absurd length from any participant
//   on the domain would otherwise throw through Fast DDS into the reading thread and end the process;
// - getKey() is serialised: the generated one computes the key in buffers of the type object,
//   which every writer and reader of the type in a participant shares, so two writers writing at
//   once on their own threads raced on them (ThreadSanitizer: two timers' readyStatus writers).
#define CPM_TYPE_DEFINITIONS_(SPECIFIER, T, PubSub)                                                \
    SPECIFIER ::eprosima::fastdds::dds::TopicDataType* cpm::TopicType<T>::make_type_support()     \
    {                                                                                              \
        struct Guarded final : PubSub                                                              \
        {                                                                                          \
            bool deserialize(::eprosima::fastrtps::rtps::SerializedPayload_t* payload, void* data) override \
            {                                                                                      \
                try {                                                                              \
                    return PubSub::deserialize(payload, data);                                     \
                } catch (const std::exception&) {                                                  \
                    return false;                                                                  \
                }                                                                                  \
            }                                                                                      \
            bool getKey(void* data, ::eprosima::fastrtps::rtps::InstanceHandle_t* handle, bool force_md5) override \
            {                                                                                      \
                const std::lock_guard<std::mutex> lock(key_mutex);                                 \
                return PubSub::getKey(data, handle, force_md5);                                    \
            }                                                                                      \
            std::mutex key_mutex;                                                                  \
        };                                                                                         \
        return new Guarded();                                                                      \
    }                                                                                              \
    SPECIFIER bool cpm::TopicType<T>::decode(const std::vector<uint8_t>& cdr, T& out)             \
    {                                                                                              \
        const std::unique_ptr<::eprosima::fastdds::dds::TopicDataType> type(make_type_support()); \
        ::eprosima::fastrtps::rtps::SerializedPayload_t payload(static_cast<uint32_t>(cdr.size())); \
        for (size_t i = 0; i < cdr.size(); ++i) payload.data[i] = cdr[i];                         \
        payload.length = static_cast<uint32_t>(cdr.size());                                        \
        return type->deserialize(&payload, &out);                                                  \
    }
