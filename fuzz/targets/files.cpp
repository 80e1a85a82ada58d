// The lab's files: a world map, a lane graph, a camera file, a scenario. Each either loads or
// throws the documented error (std::runtime_error and its kin: cpm::Error, ScenarioError) whose
// message names the file; any other exception escaping is a finding.
#include "../Fuzz.hpp"

#include <cpm/aruco/Calibration.hpp>
#include <cpm/aruco/Camera.hpp>
#include <cpm/lab/Scenario.hpp>
#include <cpm/routing/LaneGraph.hpp>
#include <cpm/vehicle/World.hpp>

#include <stdexcept>

namespace fuzz_files {

void names_the_file(const std::runtime_error& e, const std::string& file)
{
    cpm::fuzz::expect(std::string(e.what()).find(file) != std::string::npos, "an error that does not name the file");
}

}  // namespace fuzz_files

CPM_FUZZ_TARGET(world)
{
    try {
        const auto world = cpm::vehicle::World::parse(cpm::fuzz::text(data, size), "fuzz_world.json");
        // What it writes it reads back the same.
        const auto again = cpm::vehicle::World::parse(world.to_json(), "again.json");
        cpm::fuzz::expect(again.to_json() == world.to_json(), "World::parse(to_json()) differs");
    } catch (const std::runtime_error& e) {
        fuzz_files::names_the_file(e, "fuzz_world.json");
    }
    return 0;
}

CPM_FUZZ_TARGET(lane_graph)
{
    const auto load = cpm::routing::parse_lane_graph(cpm::fuzz::text(data, size), "fuzz_lanes.json");
    cpm::fuzz::expect(load.ok() == load.errors.empty(), "a lane graph with errors, or none without");
    for (const auto& e : load.errors) cpm::fuzz::expect(e.text().find("fuzz_lanes.json") != std::string::npos, "an error that does not name the file");
    if (load.ok() && !load.value->nodes.empty() && !load.value->edges.empty()) {
        const auto& g = *load.value;
        (void)g.shortest_path(0, g.nodes.size() - 1);
        (void)g.pose_at(0, g.edges[0].length() / 2);
        (void)g.project(g.pose_at(g.edges.size() - 1, 0));
    }
    return 0;
}

CPM_FUZZ_TARGET(camera)
{
    const auto file = cpm::fuzz::scratch_file("camera.yaml", data, size);
    try {
        (void)cpm::aruco::Camera::load(file);
    } catch (const std::runtime_error& e) {
        fuzz_files::names_the_file(e, file);
    }
    try {
        (void)cpm::aruco::CharucoBoard::parse(cpm::fuzz::text(data, size));
    } catch (const cpm::Error&) {
    }
    return 0;
}

CPM_FUZZ_TARGET(scenario)
{
    const auto file = cpm::fuzz::scratch_file("scenario.yaml", data, size);
    try {
        (void)cpm::lab::load_scenario(file);
    } catch (const cpm::lab::ScenarioError& e) {
        cpm::fuzz::expect(!e.errors().empty(), "a ScenarioError without errors");
        for (const auto& line : e.errors())
            cpm::fuzz::expect(line.find("scenario.yaml") != std::string::npos, "a scenario error that does not name the file");
    }
    return 0;
}
