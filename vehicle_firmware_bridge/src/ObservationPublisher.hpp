#pragma once
#include <cpm/Writer.hpp>

#include <VehicleObservation.h>

#include <condition_variable>
#include <cstdint>
#include <map>
#include <mutex>
#include <thread>

namespace cpm::vehicle {

/// Writes the simulated cars' true poses from a thread of its own. A DDS write can stall for
/// seconds - Fast DDS 2.9 waits a second per send, again and again, on the shared-memory port of
/// a reader whose process was killed while holding that port's lock - and the car's
/// microcontroller (its clock, its line, its watchdog) must not wait for it, as a real one never
/// waits for the lab's network. Only the newest pose of each car waits to be written.
class ObservationPublisher
{
public:
    explicit ObservationPublisher(Writer<VehicleObservation>& writer);
    /// Returns once a write under way has ended; the poses still waiting are dropped.
    ~ObservationPublisher();
    ObservationPublisher(const ObservationPublisher&) = delete;
    ObservationPublisher& operator=(const ObservationPublisher&) = delete;

    /// Hands the pose over to be written; replaces one of the same car still waiting.
    void publish(const VehicleObservation& observation);

private:
    void run();

    Writer<VehicleObservation>& writer_;
    std::mutex mutex_;
    std::condition_variable ready_;
    std::map<uint8_t, VehicleObservation> waiting_;
    bool running_ = true;
    std::thread thread_;  // last: starts once the rest exists
};

}  // namespace cpm::vehicle
