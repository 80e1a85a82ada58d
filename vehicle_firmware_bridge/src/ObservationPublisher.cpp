#include "ObservationPublisher.hpp"

namespace cpm::vehicle {

ObservationPublisher::ObservationPublisher(Writer<VehicleObservation>& writer) : writer_(writer), thread_([this] { run(); }) {}

ObservationPublisher::~ObservationPublisher()
{
    {
        std::lock_guard<std::mutex> lock(mutex_);
        running_ = false;
    }
    ready_.notify_one();
    thread_.join();
}

void ObservationPublisher::publish(const VehicleObservation& observation)
{
    {
        std::lock_guard<std::mutex> lock(mutex_);
        waiting_[observation.vehicle_id()] = observation;
    }
    ready_.notify_one();
}

void ObservationPublisher::run()
{
    for (;;) {
        std::map<uint8_t, VehicleObservation> batch;
        {
            std::unique_lock<std::mutex> lock(mutex_);
            ready_.wait(lock, [&] { return !waiting_.empty() || !running_; });
            if (waiting_.empty()) return;  // stopped, and the last poses written
            batch.swap(waiting_);
        }
        for (const auto& [id, o] : batch) (void)writer_.write(o);
    }
}

}  // namespace cpm::vehicle
