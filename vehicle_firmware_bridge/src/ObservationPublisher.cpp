#include "ObservationPublisher.hpp"

namespace cpm::vehicle {

ObservationPublisher::ObservationPublisher(Writer<VehicleObservation>& writer) : writer_(writer), thread_([this] { run(); }) {}

ObservationPublisher::~ObservationPublisher()
{
    {
        std::lock_guard<std::mutex> lock(mutex_);
        running_ = false;
        waiting_.clear();  // a pose of the moment the car stops: not worth a stalled write per car
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
            if (!running_) return;
            batch.swap(waiting_);
        }
        for (const auto& [id, o] : batch) (void)writer_.write(o);
    }
}

}  // namespace cpm::vehicle
