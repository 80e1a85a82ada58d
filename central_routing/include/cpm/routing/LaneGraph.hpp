#pragma once
#include <cpm/Diagnostics.hpp>
// The lane graph central_routing plans on: nodes (junction poses) and directed edges (lane centre
// lines as points at most 5 cm apart), loaded from JSON and checked (every error at once, each
// with its JSON path), with the geometry the planner needs: arc length, pose at s, projection of
// a pose onto the graph, shortest paths. No DDS here.
#include <cpm/vehicle/VehicleModel.hpp>

#include <Eigen/Core>

#include <optional>
#include <string>
#include <vector>

namespace cpm::routing {

using Vec2 = Eigen::Vector2d;
using cpm::vehicle::Pose;

struct LaneNode
{
    int id = 0;
    Vec2 p{0, 0};
    double yaw = 0;
};

struct LaneEdge
{
    size_t from = 0, to = 0;     ///< indices into LaneGraph::nodes
    std::vector<Vec2> points;    ///< the lane centre line, from the `from` node to the `to` node
    std::vector<double> s;       ///< arc length at each point; s.back() is the edge's length
    double length() const { return s.back(); }
};

/// Where a pose lies on the graph.
struct Projection
{
    size_t edge = 0;
    double s = 0;          ///< arc length along the edge
    double distance = 0;   ///< m, from the pose to the lane centre line
    double yaw_error = 0;  ///< rad, the pose's heading against the lane's
};

class LaneGraph
{
public:
    double lane_width = 0;
    std::vector<LaneNode> nodes;
    std::vector<LaneEdge> edges;
    std::vector<std::vector<size_t>> successors;  ///< per edge: the edges that leave its end node

    /// The pose at arc length s along an edge (clamped to the edge), heading along the lane.
    Pose pose_at(size_t edge, double s) const;
    /// The nearest lane within max_distance whose heading is within max_yaw of the pose's.
    std::optional<Projection> project(const Pose& pose, double max_distance = 0.3, double max_yaw = 0.8) const;
    /// The shortest chain of edges from the end of `from_edge` to node `goal_node` (an index),
    /// `from_edge` first; empty when the goal cannot be reached.
    std::vector<size_t> shortest_path(size_t from_edge, size_t goal_node) const;
    /// The index of the node with this id, or nullopt.
    std::optional<size_t> node_index(int id) const;
    double total_length() const;
};

/// The outcome of loading: every error (`SOURCE: $.json.path: what is wrong`); a graph only when
/// there is none.
using GraphLoad = cpm::LoadResult<LaneGraph>;

GraphLoad parse_lane_graph(const std::string& json_text, const std::string& source);
GraphLoad load_lane_graph(const std::string& path);
/// As load_lane_graph, but throws cpm::FileError listing every error.
LaneGraph load_lane_graph_or_throw(const std::string& path);

}  // namespace cpm::routing
