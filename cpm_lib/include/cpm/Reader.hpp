#pragma once
#include <chrono>
#include <memory>
#include <string>

#include <cpm/Error.hpp>
#include <cpm/Participant.hpp>
#include <cpm/ReaderOptions.hpp>
#include <cpm/SampleResult.hpp>
#include <cpm/detail/ReaderCore.hpp>
#include <cpm/detail/SelectorGlue.hpp>

namespace cpm {

/// Reads the newest valid sample of a stamped type T (cpm_lab's Reader).
///
/// Arriving samples are buffered (up to options.buffer_capacity; the earliest arrivals go
/// first). get_sample(t_now) returns, among buffered samples with valid_after_stamp <= t_now,
/// the one with the largest create_stamp (a tie goes to the later arrival), so out-of-order
/// arrival does not matter. Every sample that can no longer win is then dropped; with no
/// valid sample nothing is dropped. With options.vehicle_id set, other vehicles' samples
/// are ignored. Thread-safe. Throws cpm::Error only at construction.
/// Not movable: DDS's receive thread calls into this very object from the moment it is
/// made. To move one, hold it in a std::unique_ptr.
template <class T>
class Reader
{
    static_assert(detail::HasHeader<T>::value, "Reader<T> needs a type whose first member is `Header header`");

public:
    Reader(Reader&&) = delete;
    Reader& operator=(Reader&&) = delete;

    explicit Reader(const std::string& topic, ReaderOptions options = {})
        : Reader(Participant::default_participant(), topic, options)
    {
    }
    Reader(Participant& participant, const std::string& topic, ReaderOptions options = {})
        : selector_(options.buffer_capacity),
          vehicle_filter_(vehicle_filter(topic, options)),
          core_(participant.core(), topic, &detail::make_type_support<T>, options, "Reader",
                [this](void* s) { detail::with_lent<T>(s, [this](T& t) { buffer(std::move(t)); }); })
    {
    }

    /// The newest valid sample at t_now (ns) and its age t_now - valid_after_stamp.
    SampleResult<T> get_sample(uint64_t t_now)
    {
        return detail::select_sample<T>(selector_, t_now);
    }

    /// cpm_lab's form: sample_out and age_out are set only when a valid sample exists;
    /// otherwise age_out is set to UINT64_MAX.
    void get_sample(uint64_t t_now, T& sample_out, uint64_t& age_out)
    {
        auto result = get_sample(t_now);
        if (result.valid) {
            sample_out = std::move(result.sample);
            age_out = result.age_ns;
        } else {
            age_out = UINT64_MAX;
        }
    }

    /// Waits until a sample (of options.vehicle_id, when set) arrives after the last call that
    /// returned true, or the timeout: for code that acts on each new sample, then calls
    /// get_sample. One thread should wait per reader. True when a sample arrived.
    bool wait_for_new_sample(std::chrono::nanoseconds timeout) { return selector_.wait_for_arrival(timeout); }

    size_t matched_publications() const { return core_.matched_publications(); }
    [[nodiscard]] bool wait_for_matched(size_t n, std::chrono::milliseconds timeout) const
    {
        return core_.wait_for_matched(n, timeout);
    }
    /// Samples dropped because the buffer was full (raise buffer_capacity if this grows).
    uint64_t overflow_count() const { return selector_.overflow_count(); }

private:
    static int vehicle_filter(const std::string& topic, const ReaderOptions& options)
    {
        if (!options.vehicle_id) return -1;
        if constexpr (!detail::HasVehicleId<T>::value) {
            throw Error("Reader on topic '" + topic + "': option vehicle_id is set but the type has no vehicle_id");
        }
        return *options.vehicle_id;
    }

    void buffer(T&& sample)
    {
        if constexpr (detail::HasVehicleId<T>::value) {
            if (vehicle_filter_ >= 0 && sample.vehicle_id() != vehicle_filter_) return;
        }
        detail::add_sample(selector_, std::move(sample));
    }

    detail::SampleSelector selector_;
    int vehicle_filter_;
    detail::ReaderCore core_;  // last: its DDS thread feeds the members above
};

}  // namespace cpm
