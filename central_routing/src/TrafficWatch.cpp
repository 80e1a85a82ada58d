#include <cpm/routing/TrafficWatch.hpp>

#include <cmath>
#include <cstdio>

namespace cpm::routing {

void TrafficWatch::add(int id, uint64_t t_ns, const Pose& pose)
{
    Car& c = cars_[id];
    if (!c.seen) {
        c.seen = true;
        c.anchor = pose, c.anchor_ns = t_ns;
    } else {
        if (t_ns < c.last_ns) return;  // late: the newer pose stands
        c.distance += std::hypot(pose.x - c.last.x, pose.y - c.last.y);
        if (std::hypot(pose.x - c.anchor.x, pose.y - c.anchor.y) > 0.02) {
            c.anchor = pose, c.anchor_ns = t_ns;
        } else {
            c.longest_standstill = std::max(c.longest_standstill, double(t_ns - c.anchor_ns) * 1e-9);
        }
    }
    c.last = pose, c.last_ns = t_ns;
    for (const auto& [other_id, other] : cars_) {
        if (other_id == id || t_ns - other.last_ns > 40'000'000 || other.last_ns > t_ns + 40'000'000) continue;
        const double d = footprint_distance(footprint_, pose, other.last);
        const auto pair = std::minmax(id, other_id);
        if (d < min_distance_) min_distance_ = d, closest_ = pair;
        bool& touching = touching_[pair];
        if (d <= 0 && !touching) ++overlaps_;
        touching = d <= 0;
    }
}

std::string TrafficWatch::report() const
{
    std::string out;
    char line[160];
    for (const auto& [id, c] : cars_) {
        std::snprintf(line, sizeof line, "vehicle %d: drove %.1f m, stood still at most %.1f s\n", id, c.distance, c.longest_standstill);
        out += line;
    }
    if (min_distance_ < 1e299) {
        std::snprintf(line, sizeof line, "smallest distance between two cars' bodies: %.3f m (vehicles %d and %d)%s\n", min_distance_,
                      closest_.first, closest_.second, overlaps_ ? "" : "; they never touched");
        out += line;
    }
    if (overlaps_) {
        std::snprintf(line, sizeof line, "cars touched %zu time(s)\n", overlaps_);
        out += line;
    }
    return out;
}

}  // namespace cpm::routing
