#pragma once
#include <chrono>
#include <string>

#include <cpm/Participant.hpp>
#include <cpm/WriterOptions.hpp>
#include <cpm/detail/WriterCore.hpp>

namespace cpm {

/// Publishes samples of T on one topic.
/// Throws cpm::Error at construction when the topic name is empty, the topic exists in
/// the participant with another type, or DDS refuses the options. write() never throws.
/// Movable (not copyable): the DDS entity moves along; a moved-from Writer may only be destroyed
/// or assigned to.
template <class T>
class Writer
{
public:
    explicit Writer(const std::string& topic, WriterOptions options = {})
        : Writer(Participant::default_participant(), topic, options)
    {
    }
    Writer(Participant& participant, const std::string& topic, WriterOptions options = {})
        : core_(participant.core(), topic, &detail::make_type_support<T>, options)
    {
    }

    /// Publishes one sample. False when DDS refused it (a keep-all history stayed full
    /// for 100 ms, or the writer is broken). Thread-safe.
    [[nodiscard]] bool write(const T& sample) { return core_.write(&sample); }

    /// Readers matched right now (goes down again when a reader goes away).
    size_t matched_subscriptions() const { return core_.matched_subscriptions(); }
    /// Waits until at least n readers are matched; false on timeout.
    [[nodiscard]] bool wait_for_matched(size_t n, std::chrono::milliseconds timeout) const
    {
        return core_.wait_for_matched(n, timeout);
    }
    /// Waits until every matched reliable reader acknowledged all samples; false on timeout.
    bool wait_for_acknowledgments(std::chrono::milliseconds timeout)
    {
        return core_.wait_for_acknowledgments(timeout);
    }
    const std::string& topic() const { return core_.topic(); }

private:
    detail::WriterCore core_;
};

}  // namespace cpm
