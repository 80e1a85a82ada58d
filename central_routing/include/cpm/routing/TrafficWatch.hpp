#pragma once
// Judges cars by their true poses as they come (VehicleObservation): the smallest distance
// between two bodies, how far each car drove and its longest standstill. No DDS here; `cpm
// routing watch` and the tests feed it.
#include <cpm/routing/Conflicts.hpp>

#include <cstdint>
#include <map>
#include <string>

namespace cpm::routing {

class TrafficWatch
{
public:
    explicit TrafficWatch(Footprint footprint = {}) : footprint_(footprint) {}

    /// A car's pose at t_ns. Bodies are compared with the other cars' newest poses no older
    /// than 40 ms.
    void add(int id, uint64_t t_ns, const Pose& pose);

    struct Car
    {
        double distance = 0;           ///< m driven
        double longest_standstill = 0; ///< s within 2 cm of one place
        uint64_t anchor_ns = 0, last_ns = 0;
        Pose anchor, last;
        bool seen = false;
    };
    const std::map<int, Car>& cars() const { return cars_; }
    /// m between the two closest bodies seen (infinity before two cars were seen together).
    double min_distance() const { return min_distance_; }
    /// The pair that came closest.
    std::pair<int, int> closest() const { return closest_; }
    /// Body overlaps seen (times two cars began to touch).
    size_t overlaps() const { return overlaps_; }
    /// One line per car and the smallest distance, for people.
    std::string report() const;

private:
    Footprint footprint_;
    std::map<int, Car> cars_;
    std::map<std::pair<int, int>, bool> touching_;
    double min_distance_ = 1e300;
    std::pair<int, int> closest_{0, 0};
    size_t overlaps_ = 0;
};

}  // namespace cpm::routing
