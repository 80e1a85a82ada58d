#pragma once
#include <chrono>
#include <string>
#include <vector>

#include <cpm/Participant.hpp>
#include <cpm/ReaderOptions.hpp>
#include <cpm/detail/ReaderCore.hpp>

namespace cpm {

/// A plain DDS reader: take() what arrived, wait for data, see the match count.
/// Thread-safe. Throws cpm::Error only at construction.
/// Movable (not copyable): the DDS entity moves along; a moved-from ReaderAbstract may only be destroyed
/// or assigned to.
template <class T>
class ReaderAbstract
{
public:
    explicit ReaderAbstract(const std::string& topic, ReaderOptions options = {})
        : ReaderAbstract(Participant::default_participant(), topic, options)
    {
    }
    ReaderAbstract(Participant& participant, const std::string& topic, ReaderOptions options = {})
        : core_(participant.core(), topic, &detail::make_type_support<T>, options, "ReaderAbstract")
    {
    }

    /// The samples received since the last call, in arrival order (up to the DDS history
    /// the options keep: history_depth per instance, or all with keep_all).
    std::vector<T> take()
    {
        std::vector<T> samples;
        core_.drain([&](void* s) { detail::with_lent<T>(s, [&](T& t) { samples.push_back(std::move(t)); }); });
        return samples;
    }

    /// Takes what arrived, like take(), but passes each sample to `each(const T&)` where it
    /// lies instead of moving it into a vector. Shared by a writer with data_sharing and a plain
    /// type (Writer::write_in_place), that is the writer's memory: nothing is copied (a type with
    /// 8-byte fields lies misaligned there and is passed as an aligned copy). Keep
    /// `each` short: the sample's slot returns to the writer afterwards (a writer that needs
    /// it back sooner overwrites it, which is logged). Returns how many samples were passed.
    template <class Each>
    size_t take_each(Each&& each)
    {
        return core_.drain([&](void* s) { detail::with_lent<T>(s, [&](const T& t) { each(t); }); });
    }

    /// Waits until a sample can be taken; false on timeout.
    [[nodiscard]] bool wait_for_data(std::chrono::milliseconds timeout) { return core_.wait_for_data(timeout); }

    size_t matched_publications() const { return core_.matched_publications(); }
    [[nodiscard]] bool wait_for_matched(size_t n, std::chrono::milliseconds timeout) const
    {
        return core_.wait_for_matched(n, timeout);
    }

private:
    detail::ReaderCore core_;
};

}  // namespace cpm
