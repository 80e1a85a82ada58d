#pragma once
#include <chrono>
#include <memory>
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

    /// Fills a sample in place and publishes it: `fill(T&)` sets every field, for a lent sample
    /// holds an earlier sample's bytes. With data_sharing and a plain type (fixed-size fields
    /// only, no sequence or string) aligned to at most 4 bytes (see shares_in_place()) the sample
    /// lies in shared memory and readers on this host read it there: no copy between the
    /// processes, none into DDS. A plain type without data sharing is still not copied into DDS;
    /// any other type, and a plain type that Fast DDS would lend misaligned, is filled in a new
    /// sample and written as by write(). False as for write(); an exception from fill passes
    /// through and nothing is published.
    template <class Fill>
    [[nodiscard]] bool write_in_place(Fill&& fill)
    {
        void* lent = core_.loan();
        if (lent != nullptr && !detail::aligned_for<T>(lent)) {
            core_.discard_loan(lent);  // a T& there would be undefined behaviour
            lent = nullptr;
        }
        if (lent != nullptr) {
            try {
                fill(*static_cast<T*>(lent));
            } catch (...) {
                core_.discard_loan(lent);
                throw;
            }
            return core_.write_loan(lent);
        }
        auto sample = std::make_unique<T>();
        fill(*sample);
        return core_.write(sample.get());
    }
    /// Whether write_in_place() hands readers on this host the very memory it filled: with
    /// data_sharing, for a plain type whose alignment is at most 4 (Fast DDS 2.9 lays shared
    /// samples 4 bytes past an 8-byte boundary, so a type with 8-byte fields is copied instead;
    /// give a zero-copy type 4-byte fields: `unsigned long`, `float`, octet arrays).
    bool shares_in_place() const
    {
        return core_.loans_are_shared() && alignof(T) <= detail::kLentSampleAlignment;
    }

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
