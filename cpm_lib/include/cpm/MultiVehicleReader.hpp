#pragma once
#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <tuple>
#include <vector>

#include <cpm/Error.hpp>
#include <cpm/Participant.hpp>
#include <cpm/ReaderOptions.hpp>
#include <cpm/SampleResult.hpp>
#include <cpm/detail/ReaderCore.hpp>
#include <cpm/detail/SelectorGlue.hpp>

namespace cpm {

/// One reader for many vehicles of a keyed topic: get_samples(t_now) applies Reader's rule
/// (newest valid by create_stamp, age = t_now - valid_after_stamp) per configured vehicle.
/// Samples of other vehicle ids are ignored. Each vehicle's buffer holds up to
/// options.buffer_capacity samples. Thread-safe. Throws cpm::Error only at construction.
/// Not movable: DDS's receive thread calls into this very object from the moment it is
/// made. To move one, hold it in a std::unique_ptr.
template <class T>
class MultiVehicleReader
{
    static_assert(detail::HasHeader<T>::value && detail::HasVehicleId<T>::value,
                  "MultiVehicleReader<T> needs `Header header` and `@key octet vehicle_id`");

public:
    MultiVehicleReader(MultiVehicleReader&&) = delete;
    MultiVehicleReader& operator=(MultiVehicleReader&&) = delete;

    MultiVehicleReader(const std::string& topic, std::vector<uint8_t> vehicle_ids, ReaderOptions options = {})
        : MultiVehicleReader(Participant::default_participant(), topic, std::move(vehicle_ids), options)
    {
    }
    /// Vehicles 1..n_vehicles, inclusive.
    MultiVehicleReader(const std::string& topic, int n_vehicles, ReaderOptions options = {})
        : MultiVehicleReader(Participant::default_participant(), topic, ids_up_to(topic, n_vehicles), options)
    {
    }
    MultiVehicleReader(Participant& participant, const std::string& topic, std::vector<uint8_t> vehicle_ids,
                       ReaderOptions options = {})
        : buffers_(make_buffers(topic, vehicle_ids, options.buffer_capacity)),
          core_(participant.core(), topic, &detail::make_type_support<T>, options, "MultiVehicleReader",
                [this](void* s) { detail::with_lent<T>(s, [this](T& t) { buffer(std::move(t)); }); })
    {
    }

    /// For every configured vehicle: its newest valid sample at t_now and its age.
    std::map<uint8_t, SampleResult<T>> get_samples(uint64_t t_now)
    {
        std::map<uint8_t, SampleResult<T>> results;
        for (auto& [id, selector] : buffers_) results[id] = detail::select_sample<T>(*selector, t_now);
        return results;
    }

    /// One configured vehicle's newest valid sample at t_now and its age (invalid for an id
    /// that is not configured: reading never throws).
    SampleResult<T> get_sample(uint8_t vehicle_id, uint64_t t_now)
    {
        auto it = buffers_.find(vehicle_id);
        if (it == buffers_.end()) return {};
        return detail::select_sample<T>(*it->second, t_now);
    }
    /// cpm_lab's form: vehicles without a valid sample get age UINT64_MAX and a default sample.
    void get_samples(uint64_t t_now, std::map<uint8_t, T>& samples_out, std::map<uint8_t, uint64_t>& ages_out)
    {
        for (auto& [id, result] : get_samples(t_now)) {
            samples_out[id] = std::move(result.sample);
            ages_out[id] = result.valid ? result.age_ns : UINT64_MAX;
        }
    }

    size_t matched_publications() const { return core_.matched_publications(); }
    [[nodiscard]] bool wait_for_matched(size_t n, std::chrono::milliseconds timeout) const
    {
        return core_.wait_for_matched(n, timeout);
    }

private:
    using Buffers = std::map<uint8_t, std::unique_ptr<detail::SampleSelector>>;

    static std::vector<uint8_t> ids_up_to(const std::string& topic, int n)
    {
        if (n < 1 || n > 255) {
            throw Error("MultiVehicleReader on topic '" + topic + "': n_vehicles = " + std::to_string(n) +
                        " is outside 1..255");
        }
        std::vector<uint8_t> ids;
        for (int id = 1; id <= n; ++id) ids.push_back(static_cast<uint8_t>(id));
        return ids;
    }
    static Buffers make_buffers(const std::string& topic, const std::vector<uint8_t>& ids, size_t capacity)
    {
        if (ids.empty()) throw Error("MultiVehicleReader on topic '" + topic + "': no vehicle ids given");
        Buffers buffers;
        for (uint8_t id : ids) buffers.emplace(id, std::make_unique<detail::SampleSelector>(capacity));
        return buffers;
    }
    void buffer(T&& sample)
    {
        auto it = buffers_.find(sample.vehicle_id());
        if (it == buffers_.end()) return;
        detail::add_sample(*it->second, std::move(sample));
    }

    const Buffers buffers_;     // fixed after construction: safe to read from any thread
    detail::ReaderCore core_;   // last: its DDS thread feeds buffers_
};

}  // namespace cpm
