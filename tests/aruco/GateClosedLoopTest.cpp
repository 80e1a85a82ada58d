// The gate course in-process: the simulated car (FirmwareSim through the bridge's command path),
// the synthetic camera, real OpenCV detection and pose, and fsm_node's machine
// scenarios/fsm/gates.json, at 50 Hz with the camera at 25 Hz one frame late. Courses are
// generated from seeds: gate offsets ±0.3 m, angles ±30°, start headings ±45°.
#include <cpm/aruco/Camera.hpp>
#include <cpm/aruco/Detector.hpp>
#include <cpm/aruco/GateCourse.hpp>
#include <cpm/aruco/Renderer.hpp>
#include <cpm/fsm/Loader.hpp>
#include "../fsm/ClosedLoopCar.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <cpm_test/SourceDir.hpp>

using namespace cpm;

namespace {

struct Run
{
    std::vector<aruco::PathPoint> path;
    bool stopped = false;
    int wall_hits = 0;
};

Run drive(const vehicle::World& world, vehicle::Pose start, double seconds)
{
    vehicle::VehicleParameters params;
    cpm_test::ClosedLoopCar car(params, world, start);
    const auto camera = aruco::Camera::load(cpm_test::source_dir() + "/scenarios/cameras/sim_640x480.yaml");
    aruco::Renderer renderer(world, camera, {.noise_sigma = 2, .seed = 3});
    aruco::MarkerDetector detector(camera, {}, aruco::MarkerSizes::from_world(world));
    auto loaded = fsm::load_file(cpm_test::source_dir() + "/scenarios/fsm/gates.json");
    EXPECT_TRUE(loaded.ok()) << (loaded.errors.empty() ? "" : loaded.errors[0].text());
    Run run;
    if (!loaded.ok()) return run;
    auto& machine = *loaded.machine;
    std::vector<fsm::MarkerSighting> seen;  // the newest frame's markers (one frame late)
    for (int cycle = 0; cycle < int(seconds * 50); ++cycle) {
        fsm::Inputs in = car.step();
        in.markers = seen;
        if (cycle % 2 == 0) {
            seen.clear();
            for (const auto& m : detector.observe(renderer.render(car.pose()))) {
                if (m.has_pose) seen.push_back({m.id, m.x, m.y, m.yaw, m.distance});
            }
        }
        auto out = machine.tick(in, 0.02);
        car.command(out);
        run.path.push_back({in.t, car.pose()});
        if (std::getenv("GATE_TRACE") && cycle % 10 == 0) {
            const auto& p = car.pose();
            std::string ids;
            for (const auto& m : in.markers) {
                // Each marker's position as seen, in the world through the true pose.
                char text[64];
                std::snprintf(text, sizeof text, " %d@(%.2f,%.2f)", m.id, p.x + std::cos(p.yaw) * m.x - std::sin(p.yaw) * m.y,
                              p.y + std::sin(p.yaw) * m.x + std::cos(p.yaw) * m.y);
                ids += text;
            }
            std::printf("t %.1f state %d (%s) pose %.2f %.2f %.2f steer %.2f markers%s\n", in.t, machine.active().id(),
                        machine.active().type().c_str(), p.x, p.y, p.yaw, out.steering, ids.c_str());
        }
        if (machine.in_final_state() && std::abs(car.car().model().speed()) < 1e-3) {
            run.stopped = true;
            break;
        }
    }
    run.wall_hits = int(car.car().stats().wall_collisions);
    return run;
}

}  // namespace

// GATE_FIRST_SEED=N runs the eight courses from seed N (GATE_TRACE=1 prints each drive).
TEST(GateClosedLoop, PassesEveryGateOfGeneratedCoursesInOrder)
{
    const vehicle::VehicleParameters params;
    int passed_courses = 0;
    const uint32_t first = std::getenv("GATE_FIRST_SEED") ? uint32_t(std::atoi(std::getenv("GATE_FIRST_SEED"))) : 1;
    for (uint32_t seed = first; seed < first + 8; ++seed) {
        const auto world = aruco::gate_course(seed);
        std::mt19937 rng(seed * 7919);
        const double heading = std::uniform_real_distribution<double>(-M_PI / 4, M_PI / 4)(rng);
        if (std::getenv("GATE_TRACE")) std::printf("%s", world.to_json().c_str());
        auto run = drive(world, {0, 0, heading}, 60);
        auto passages = aruco::gate_passages(world, run.path, params.width);
        std::string why;
        const bool ok = aruco::all_gates_passed(passages, 0.05, &why);
        std::string offsets;
        for (const auto& p : passages) offsets += " " + std::to_string(p.offset).substr(0, 6);
        EXPECT_TRUE(ok) << "seed " << seed << " heading " << heading << ": " << why << "; offsets" << offsets;
        EXPECT_TRUE(run.stopped) << "seed " << seed << ": did not stop after the last gate";
        EXPECT_EQ(run.wall_hits, 0) << "seed " << seed;
        passed_courses += ok;
        std::printf("seed %u heading %+.2f rad: %s, gate offsets%s m\n", seed, heading, ok ? "all gates passed" : why.c_str(),
                    offsets.c_str());
    }
    EXPECT_EQ(passed_courses, 8);
}
