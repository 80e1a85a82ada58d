#pragma once
// The tests' own referee of the gap between two cars' bodies, independent of the planner's
// footprint_distance (separating axes and vertex-to-edge distances): each body's outline
// sampled every millimetre, each sample's exact distance to the other body in that body's own
// frame (a rectangle about its origin: a closed form). The gap it finds is within half a
// millimetre of the true one; a sample inside the other body is an overlap (gap 0).
#include <cpm/routing/Conflicts.hpp>

#include <algorithm>
#include <cmath>

namespace routing_test {

/// The distance from a point (world frame) to a car's body at `pose`; 0 inside it.
inline double point_to_body(const cpm::routing::Footprint& f, const cpm::routing::Pose& pose, double x, double y)
{
    const double c = std::cos(pose.yaw), s = std::sin(pose.yaw);
    const double along = (x - pose.x) * c + (y - pose.y) * s, across = -(x - pose.x) * s + (y - pose.y) * c;
    const double front = f.length - f.rear_overhang, back = f.rear_overhang;
    const double centre = (front - back) / 2, half_length = (front + back) / 2;
    const double dx = std::max(0.0, std::abs(along - centre) - half_length), dy = std::max(0.0, std::abs(across) - f.width / 2);
    return std::hypot(dx, dy);
}

/// The least distance from the outline of the body at `a`, sampled every `step` metres, to the
/// body at `b`: at most step / 2 more than the true least distance, never less.
inline double outline_to_body(const cpm::routing::Footprint& f, const cpm::routing::Pose& a, const cpm::routing::Pose& b, double step = 0.001)
{
    const double c = std::cos(a.yaw), s = std::sin(a.yaw);
    const double front = f.length - f.rear_overhang, back = -f.rear_overhang, half = f.width / 2;
    const double corners[5][2] = {{front, half}, {back, half}, {back, -half}, {front, -half}, {front, half}};
    double best = 1e300;
    for (int e = 0; e < 4; ++e) {
        const double len = std::hypot(corners[e + 1][0] - corners[e][0], corners[e + 1][1] - corners[e][1]);
        const int steps = int(std::ceil(len / step));
        for (int k = 0; k <= steps; ++k) {
            const double u = double(k) / steps;
            const double px = corners[e][0] + u * (corners[e + 1][0] - corners[e][0]), py = corners[e][1] + u * (corners[e + 1][1] - corners[e][1]);
            best = std::min(best, point_to_body(f, b, a.x + px * c - py * s, a.y + px * s + py * c));
        }
    }
    return best;
}

/// The gap between the two bodies (0 when they overlap), to within half a millimetre.
inline double body_gap(const cpm::routing::Footprint& f, const cpm::routing::Pose& a, const cpm::routing::Pose& b)
{
    return std::min(outline_to_body(f, a, b), outline_to_body(f, b, a));
}

/// The least of `least` and the bodies' gap: measured to half a millimetre only when a look at
/// a 2 cm sampling (within 1 cm of the true gap) does not already show it larger.
inline double least_gap(const cpm::routing::Footprint& f, const cpm::routing::Pose& a, const cpm::routing::Pose& b, double least)
{
    const double reach = std::hypot(std::max(f.length - f.rear_overhang, f.rear_overhang), f.width / 2);
    if (std::hypot(a.x - b.x, a.y - b.y) > 2 * reach + least) return least;  // bounding circles apart
    if (std::min(outline_to_body(f, a, b, 0.02), outline_to_body(f, b, a, 0.02)) - 0.01 > least) return least;
    return std::min(least, body_gap(f, a, b));
}

}  // namespace routing_test
