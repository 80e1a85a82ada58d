#pragma once
#include <cpm/vehicle/VehicleModel.hpp>
#include <cpm/vehicle/World.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace cpm::aruco {

/// A corridor along +x with gates across it (the world format of scenarios/README.md), generated from a seed.
struct GateCourseOptions
{
    int gates = 3;
    double corridor_width = 2.4;     ///< m, walls at y = ±width/2
    double first_gate = 2.6;         ///< x of the first gate, m
    double spacing = 3.2;            ///< between gates along x, m
    double gate_width = 0.8;         ///< between the two markers' centres, m
    double marker_size = 0.2, marker_z = 0.15;
    double max_offset = 0.3;         ///< lateral offset of a gate's centre, ±m
    double max_angle = 30 * 3.14159265358979323846 / 180;  ///< gate turned by up to ±this, rad
};

/// Gate k's markers are 2k (left, seen from the car driving along +x) and 2k + 1 (right).
vehicle::World gate_course(uint32_t seed, const GateCourseOptions& options = {});

/// How a driven path went through one gate.
struct GatePassage
{
    int gate = 0;               ///< index in world.gates()
    bool passed = false;        ///< the path crossed the segment between the markers, driving through
    double t = 0;               ///< when (the path's time), s
    double offset = 0;          ///< signed distance of the crossing from the gate's centre, m (+ left)
    double clearance = 0;       ///< from the car's side to the nearer marker's inner edge, m
};

struct PathPoint
{
    double t = 0;
    vehicle::Pose pose;
};

/// Each gate's passage by a path of poses (rear axle) of a car `car_width` wide: the first
/// crossing of each gate's segment, in driving direction. Gates not crossed are not passed.
std::vector<GatePassage> gate_passages(const vehicle::World& world, const std::vector<PathPoint>& path, double car_width);

/// True when every gate was passed, in order, each with at least `min_clearance` m.
bool all_gates_passed(const std::vector<GatePassage>& passages, double min_clearance, std::string* why = nullptr);

}  // namespace cpm::aruco
