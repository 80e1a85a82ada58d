#pragma once
// Where two cars on the lane graph would come too close: the graph sampled at fixed spacing, and
// for every sample the samples of any lane where a car would be closer than the margin to a car
// there. Footprints are the cars' real bodies (from the simulator's vehicle parameters).
#include <cpm/routing/LaneGraph.hpp>

#include <cstdint>

namespace cpm::routing {

/// A car's body around its pose (the rear axle centre, as in VehicleObservation).
struct Footprint
{
    double length = 0.40, width = 0.20;
    double rear_overhang = 0.07;  ///< from the rear axle to the back of the body
    static Footprint of(const cpm::vehicle::VehicleParameters& p) { return {p.length, p.width, p.rear_overhang}; }
};

/// The distance between two cars' bodies (0 when they overlap).
double footprint_distance(const Footprint& f, const Pose& a, const Pose& b);

struct ConflictOptions
{
    Footprint footprint;
    double margin = 0.05;   ///< m: the least distance between two bodies the planner keeps
    double spacing = 0.04;  ///< m between samples along an edge
    double v_max = 1.0;     ///< m/s, and dt: how far a car moves between the planner's time steps;
    double dt = 0.05;       ///< s   the samples' bodies are lengthened to cover it
};

/// One conflict zone: samples of different lanes (not one the continuation of the other) whose
/// cars would come too close, joined while they touch — a crossing, a merge, a diverge.
struct ConflictZone
{
    Vec2 centre{0, 0};
    std::vector<uint32_t> samples;
};

class ConflictTable
{
public:
    ConflictTable(const LaneGraph& graph, const ConflictOptions& options);

    const LaneGraph& graph() const { return *graph_; }
    const ConflictOptions& options() const { return options_; }
    size_t sample_count() const { return pose_.size(); }
    /// The sample nearest to arc length s on an edge.
    uint32_t sample(size_t edge, double s) const;
    size_t edge_of(uint32_t sample) const { return edge_of_[sample]; }
    /// An edge's samples: the first, how many, and their spacing (m) from its start.
    uint32_t first_sample(size_t edge) const { return uint32_t(first_[edge]); }
    size_t samples_on(size_t edge) const { return (edge + 1 < first_.size() ? first_[edge + 1] : pose_.size()) - first_[edge]; }
    double sample_step(size_t edge) const { return step_[edge]; }
    const Pose& pose(uint32_t sample) const { return pose_[sample]; }
    /// Samples where a car would be closer than the margin to a car at `sample` (never itself).
    const std::vector<uint32_t>& conflicts(uint32_t sample) const { return conflicts_[sample]; }
    /// The zone a sample belongs to, or -1 (plain lane: only cars on the same lane come close).
    int zone_of(uint32_t sample) const { return zone_of_[sample]; }
    const std::vector<ConflictZone>& zones() const { return zones_; }
    size_t pair_count() const;

private:
    const LaneGraph* graph_;
    ConflictOptions options_;
    std::vector<size_t> first_;        // per edge: its first sample
    std::vector<double> step_;         // per edge: spacing of its samples
    std::vector<Pose> pose_;
    std::vector<size_t> edge_of_;
    std::vector<std::vector<uint32_t>> conflicts_;
    std::vector<int> zone_of_;
    std::vector<ConflictZone> zones_;
};

}  // namespace cpm::routing
