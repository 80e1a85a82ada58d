#pragma once
// A lane graph drawn for people: lanes with their direction, node ids, conflict zones.
#include <cpm/routing/Conflicts.hpp>

#include <string>

namespace cpm::routing {

/// A car to draw on the map: its id and pose.
struct DrawnCar
{
    int id = 0;
    Pose pose;
};

/// Writes the drawing to `path`, as SVG or PNG by its ending (.svg, .png), with `cars` drawn as
/// their bodies (the table's footprint). Throws cpm::Error for another ending or a file that
/// cannot be written.
void render_lane_graph(const ConflictTable& table, const std::string& path, const std::vector<DrawnCar>& cars = {});

}  // namespace cpm::routing
