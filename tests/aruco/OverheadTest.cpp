// The positioning system's geometry with real OpenCV: every car's pose from frames of the
// overhead camera (distorted lens) over the whole map, the image's corners included; the
// camera's own pose from floor markers; the world's and camera file's overhead fields.
#include <cpm/Error.hpp>
#include <cpm/aruco/Overhead.hpp>

#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <unistd.h>
#include <cpm_test/SourceDir.hpp>

using namespace cpm;
using namespace cpm::aruco;

namespace {

const std::string kCamera = cpm_test::source_dir() + "/scenarios/cameras/ceiling_1280x1024.yaml";
const std::string kWorld = cpm_test::source_dir() + "/scenarios/maps/lab_floor.json";

std::string error_from(const std::function<void()>& f)
{
    try {
        f();
    } catch (const Error& e) {
        return e.what();
    }
    return "(no error)";
}

std::string scratch_file(const std::string& name, const std::string& text)
{
    auto path = std::filesystem::temp_directory_path() / ("cpm_overhead_test_" + std::to_string(::getpid()) + "_" + name);
    std::ofstream(path) << text;
    return path.string();
}

double angle_diff(double a, double b) { return std::abs(std::remainder(a - b, 2 * M_PI)); }

/// A camera turned by `degrees` about `axis` (map frame) and moved by `shift` from the lab's.
Camera moved(Camera c, cv::Vec3d axis, double degrees, cv::Vec3d shift)
{
    cv::Matx33d turn;
    cv::Rodrigues(axis * (degrees * M_PI / 180 / cv::norm(axis)), turn);
    c.overhead->rotation = turn * c.overhead->rotation;
    c.overhead->position += shift;
    return c;
}

}  // namespace

TEST(OverheadWorld, RoofAndFloorMarkersAreReadAndEveryMistakeIsNamed)
{
    const auto w = vehicle::World::load(kWorld);
    ASSERT_EQ(w.roof_markers().size(), 20u);
    EXPECT_EQ(w.roof_markers()[4].vehicle_id, 5);
    EXPECT_EQ(w.roof_marker(5)->vehicle_id, 5);
    EXPECT_DOUBLE_EQ(w.roof_markers()[4].size, 0.12);
    EXPECT_EQ(w.floor_markers().size(), 6u);
    EXPECT_EQ(w.roof_marker(40), nullptr);
    // What to_json writes, load reads back.
    const auto again = vehicle::World::parse(w.to_json(), "again");
    EXPECT_EQ(again.roof_markers().size(), 20u);
    EXPECT_DOUBLE_EQ(again.floor_markers()[2].x, w.floor_markers()[2].x);

    auto error = [](const std::string& json) { return error_from([&] { vehicle::World::parse(json, "w.json"); }); };
    EXPECT_NE(error(R"({"roof_markers": {"1": {"id": 3}, "2": {"id": 3}}})").find(
                  "$.roof_markers[\"2\"].id: marker 3 is on the roofs of cars 1 and 2"),
              std::string::npos);
    EXPECT_NE(error(R"({"roof_markers": {"car1": {"id": 3}}})").find("$.roof_markers[\"car1\"]: the key must be a vehicle id 1..255"),
              std::string::npos);
    EXPECT_NE(error(R"({"roof_markers": {"1": {"id": 3, "size": -1}}})").find("$.roof_markers[\"1\"].size: must be > 0"), std::string::npos);
    EXPECT_NE(error(R"({"roof_markers": {"1": {"id": 3}}, "floor_markers": [{"id": 3, "x": 0, "y": 0, "yaw": 0}]})")
                  .find("$.floor_markers[0].id: id 3 is also the roof marker of car 1"),
              std::string::npos);
    EXPECT_NE(error(R"({"floor_markers": [{"id": 4, "x": 0, "yaw": 0}]})").find("$.floor_markers[0]: missing \"y\""), std::string::npos);
    EXPECT_NE(error(R"({"roof_marker": {}})").find("roof_markers"), std::string::npos) << "a typo is named with the key it meant";
}

TEST(OverheadCamera, TheCameraFilesPoseIsReadSavedAndDemandedWhereItIsNeeded)
{
    const Camera c = Camera::load(kCamera, CameraPlacement::overhead);
    ASSERT_TRUE(c.overhead);
    EXPECT_DOUBLE_EQ(c.overhead->position[2], 3.0);
    EXPECT_DOUBLE_EQ(c.overhead->rotation(1, 1), -1.0);
    Camera located = c;
    located.overhead->residual_px = 0.25;
    const std::string path = scratch_file("saved.yaml", "");
    located.save(path);
    const Camera back = Camera::load(path, CameraPlacement::overhead);
    EXPECT_DOUBLE_EQ(back.overhead->position[0], 2.25);
    EXPECT_DOUBLE_EQ(back.overhead->residual_px, 0.25);
    EXPECT_DOUBLE_EQ(back.distortion[0], -0.08);

    // A car's camera file has no pose in the map: the IPS says so and how to get one.
    const std::string car = cpm_test::source_dir() + "/scenarios/cameras/sim_640x480.yaml";
    EXPECT_NE(error_from([&] { Camera::load(car, CameraPlacement::overhead); }).find("sim_640x480.yaml: no overhead pose"), std::string::npos);
    EXPECT_FALSE(Camera::load(car, CameraPlacement::lens_only).overhead);
    // The lens alone: a ceiling camera file needs no mount on a car.
    EXPECT_NE(error_from([&] { Camera::load(kCamera, CameraPlacement::on_car); }).find("missing field mount_x"), std::string::npos);
    // Not a rotation.
    std::string text;
    {
        std::ifstream in(kCamera);
        text.assign(std::istreambuf_iterator<char>(in), {});
    }
    const std::string bad = text.substr(0, text.find("data: [ 1., 0., 0., 0., -1.")) + "data: [ 1., 0., 0., 0., 1., 0., 0., 0., -1. ]\n";
    const std::string bad_path = scratch_file("bad.yaml", bad);
    EXPECT_NE(error_from([&] { Camera::load(bad_path, CameraPlacement::overhead); }).find("world_rotation: not a rotation matrix"),
              std::string::npos);
    std::remove(path.c_str());
    std::remove(bad_path.c_str());  // it was left in /tmp by every run
}

TEST(OverheadLocator, EveryCarIsFoundWithin1CmAnd1DegreeOverTheWholeMapAndTheImagesCorners)
{
    const Camera camera = Camera::load(kCamera, CameraPlacement::overhead);
    const auto world = vehicle::World::load(kWorld);
    OverheadRenderer renderer(world, camera);
    OverheadLocator ips(world, camera);
    // A grid over the image, corners included (each car's centre 40 px inside the edges, where
    // its whole marker is in view), each point's place on the roof plane: the whole map and
    // beyond it. 8 cars a frame at headings that vary over the grid.
    std::vector<OverheadCar> all;
    const int nx = 11, ny = 9;
    for (int j = 0; j < ny; ++j) {
        for (int i = 0; i < nx; ++i) {
            const cv::Vec3d at = ips.on_plane({40.0f + 1199.0f * float(i) / (nx - 1), 40.0f + 943.0f * float(j) / (ny - 1)}, 0.12);
            const double yaw = std::remainder(0.7 * (i * ny + j), 2 * M_PI);
            all.push_back({0, {at[0], at[1], yaw}});
        }
    }
    ASSERT_LT(all.front().pose.x, -0.3) << "the image's corner reaches beyond the map";
    ASSERT_GT(all.back().pose.x, 4.8);
    double worst_m = 0, worst_deg = 0;
    int frames = 0, cars = 0;
    cv::Mat frame;
    std::vector<OverheadTruth> truth;
    // 8 cars at a time, far apart (every 13th grid point).
    const size_t step = (all.size() + 7) / 8;
    for (size_t first = 0; first < step; ++first) {
        std::vector<OverheadCar> in_frame;
        for (size_t k = first, id = 1; k < all.size() && id <= 8; k += step, ++id) {
            in_frame.push_back(all[k]);
            in_frame.back().vehicle_id = int(id);
        }
        renderer.render(in_frame, frame, &truth);
        ++frames;
        const OverheadView view = ips.locate(frame);
        std::map<int, const LocatedCar*> found;
        for (const auto& c : view.cars) found[c.vehicle_id] = &c;
        for (const auto& car : in_frame) {
            ASSERT_TRUE(found.count(car.vehicle_id)) << "car " << car.vehicle_id << " at " << car.pose.x << ", " << car.pose.y << " not found";
            const LocatedCar& c = *found[car.vehicle_id];
            const double d = std::hypot(c.x - car.pose.x, c.y - car.pose.y), a = angle_diff(c.yaw, car.pose.yaw) * 180 / M_PI;
            EXPECT_LT(d, 0.01) << "car at " << car.pose.x << ", " << car.pose.y;
            EXPECT_LT(a, 1.0) << "car at " << car.pose.x << ", " << car.pose.y;
            worst_m = std::max(worst_m, d);
            worst_deg = std::max(worst_deg, a);
            ++cars;
        }
        EXPECT_TRUE(view.unknown_ids.empty());
        EXPECT_TRUE(view.seen_twice.empty());
        EXPECT_GE(view.floor_markers, 4) << "floor markers hidden by no car are seen";
        EXPECT_LT(view.floor_residual_px, 0.5) << "the camera has not moved";
    }
    EXPECT_EQ(cars, nx * ny);
    std::printf("%d cars in %d frames: worst %.2f mm, %.3f°\n", cars, frames, worst_m * 1000, worst_deg);
}

TEST(OverheadLocator, TwoCarsWithOneMarkerAndMarkersOfNoCarAreNamedNotTaken)
{
    const Camera camera = Camera::load(kCamera, CameraPlacement::overhead);
    auto world = vehicle::World::load(kWorld);
    OverheadLocator ips(world, camera);
    // The renderer draws car 2 with car 1's marker (a world where both wear marker 1), and a
    // car 30 whose marker 30 is on no roof of the IPS's world.
    auto roofs = world.roof_markers();
    roofs[1].id = 1;
    roofs.push_back({30, 30, 0.12, 0.12});
    vehicle::World drawn = world;
    drawn.set_overhead_markers(roofs, world.floor_markers());
    OverheadRenderer renderer(drawn, camera);
    cv::Mat frame;
    renderer.render({{1, {1, 1, 0}}, {2, {3, 1, 0}}, {3, {2, 3, 1}}, {30, {3.5, 3, 0}}}, frame);
    const auto view = ips.locate(frame);
    ASSERT_EQ(view.cars.size(), 1u);
    EXPECT_EQ(view.cars[0].vehicle_id, 3);
    EXPECT_EQ(view.seen_twice, std::vector<int>{1});
    EXPECT_EQ(view.unknown_ids, std::vector<int>{30});
}

TEST(OverheadLocator, ACameraThatMovedShowsInTheFloorMarkersResidual)
{
    const Camera camera = Camera::load(kCamera, CameraPlacement::overhead);
    const auto world = vehicle::World::load(kWorld);
    OverheadLocator ips(world, camera);
    OverheadRenderer bumped(world, moved(camera, {0, 1, 0}, 1.0, {0.02, 0, 0}));
    cv::Mat frame;
    bumped.render({}, frame);
    const auto view = ips.locate(frame);
    EXPECT_EQ(view.floor_markers, 6);
    EXPECT_GT(view.floor_residual_px, 5.0);
}

TEST(CameraLocate, RecoversACameraPoseItNeverSawWithin1CmAnd0_2Degrees)
{
    const Camera lab = Camera::load(kCamera, CameraPlacement::overhead);
    const auto world = vehicle::World::load(kWorld);
    int n = 0;
    for (const auto& [axis, degrees, shift] : {std::tuple{cv::Vec3d(1, 0.3, 0), 2.0, cv::Vec3d(0.06, -0.07, 0.04)},
                                               {cv::Vec3d(0, 0, 1), 3.5, cv::Vec3d(-0.11, 0.05, -0.1)},
                                               {cv::Vec3d(0.2, 1, 0.5), 1.2, cv::Vec3d(0.0, 0.13, 0.2)},
                                               // tilted 1° about y only: a plane's two poses nearly alike
                                               {cv::Vec3d(0, 1, 0), 1.0, cv::Vec3d(0.06, 0, -0.05)}}) {
        const Camera truth = moved(lab, axis, degrees, shift);
        OverheadRenderer renderer(world, truth);
        cv::Mat frame;
        renderer.render({{1, {1.0, 1.2, 0.3}}, {2, {3.0, 2.5, 2.0}}}, frame);  // cars may stand in the image
        Camera lens = lab;
        lens.overhead.reset();
        const CameraLocation found = locate_camera(lens, world, frame);
        EXPECT_EQ(found.markers.size(), 6u);
        const double metres = cv::norm(found.pose.position - truth.overhead->position);
        const double deg = rotation_angle(found.pose.rotation, truth.overhead->rotation) * 180 / M_PI;
        EXPECT_LT(metres, 0.01) << "case " << n;
        EXPECT_LT(deg, 0.2) << "case " << n;
        EXPECT_LT(found.pose.residual_px, 0.5);
        EXPECT_EQ(found.unknown, (std::vector<int>{1, 2})) << "the cars' roof markers are no floor markers";
        std::printf("case %d: %.2f mm, %.4f°, residual %.3f px\n", n, metres * 1000, deg, found.pose.residual_px);
        ++n;
    }
    // Too few floor markers in view: named.
    cv::Mat blank(1024, 1280, CV_8UC1, cv::Scalar(95));
    EXPECT_EQ(error_from([&] { locate_camera(lab, world, blank); }),
              "the image shows 0 of the world's floor markers; locating the camera needs at least 2");
}
