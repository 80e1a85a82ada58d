#pragma once
#include <cpm/AsyncReader.hpp>
#include <cpm/topics.hpp>
#include <cpm/vehicle/FirmwareSimNode.hpp>

#include <VehicleObservation.h>

#include <cstdint>
#include <mutex>
#include <set>
#include <string>
#include <vector>

namespace cpm::vehicle {

/// The cars of other processes (OtherCars), fed by the reader's callback on the DDS thread that
/// receives them. A simulated car's tick runs on a real-time thread and must never call into
/// Fast DDS: a take() there waited for the reader's lock while a DDS thread of normal priority,
/// matching the writers of processes that had just started on other hosts, held it, and the
/// car's state packets stopped for 100 ms (the across-hosts test, loaded). On the simulated clock
/// an observation is in before the clock moves on, as a take() would have found it.
class OtherCarsReader
{
public:
    OtherCarsReader(Participant& participant, const std::string& topic, std::set<uint8_t> own_ids)
        : own_(std::move(own_ids)), reader_([this](std::vector<VehicleObservation>& batch) { take(batch); }, participant, topic,
                  topics::vehicle_observation.reader.on_dds_thread())
    {
    }
    /// The other cars seen within the second before `now_ns`.
    std::vector<Pose> current(uint64_t now_ns)
    {
        std::lock_guard<std::mutex> lock(mutex_);
        return cars_.current(now_ns);
    }

private:
    void take(std::vector<VehicleObservation>& batch)
    {
        std::lock_guard<std::mutex> lock(mutex_);
        for (const auto& o : batch) {
            if (own_.count(o.vehicle_id())) continue;
            cars_.seen(o.vehicle_id(), o.header().create_stamp().nanoseconds(), {o.pose().x(), o.pose().y(), o.pose().yaw()});
        }
    }

    const std::set<uint8_t> own_;
    std::mutex mutex_;
    OtherCars cars_;
    AsyncReader<VehicleObservation> reader_;  ///< last: its callback uses the members above
};

}  // namespace cpm::vehicle
