// The perception library with real OpenCV: camera files, the mount transform, the synthetic
// camera (projection, culling, occlusion) and detection + pose against its ground truth.
#include <cpm/Error.hpp>
#include <cpm/aruco/Camera.hpp>
#include <cpm/aruco/Detector.hpp>
#include <cpm/aruco/Renderer.hpp>

#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

using namespace cpm;
using namespace cpm::aruco;

namespace {

Camera test_camera(double pitch = 0)
{
    return Camera::ideal(640, 480, 70 * M_PI / 180, CameraMount{0.15, 0.02, 0.12, 0, pitch});
}

/// One marker `id` of side `size` standing at (x, y, z), facing `yaw`.
vehicle::World one_marker(double x, double y, double yaw, double size = 0.1, double z = 0.12, int id = 7)
{
    return vehicle::World({}, {vehicle::Marker{id, x, y, yaw, size, z}});
}

std::string temp_file(const std::string& name, const std::string& text)
{
    auto path = std::filesystem::temp_directory_path() / ("cpm_aruco_test_" + std::to_string(::getpid()) + "_" + name);
    std::ofstream(path) << text;
    return path.string();
}

std::string error_of(const std::function<void()>& f)
{
    try {
        f();
    } catch (const Error& e) {
        return e.what();
    }
    return "(no error)";
}

}  // namespace

TEST(ArucoCamera, MountTransformTakesCameraPointsIntoTheCarFrame)
{
    // Straight ahead of the camera (its z) is the car's x; its x (right) is the car's -y; its y
    // (down) the car's -z; the mount's offset is added.
    Camera c = test_camera();
    auto ahead = c.to_car({0, 0, 2});
    EXPECT_NEAR(ahead[0], 2.15, 1e-12);
    EXPECT_NEAR(ahead[1], 0.02, 1e-12);
    EXPECT_NEAR(ahead[2], 0.12, 1e-12);
    auto right = c.to_car({1, 0, 0});
    EXPECT_NEAR(right[1], 0.02 - 1, 1e-12);
    auto down = c.to_car({0, 1, 0});
    EXPECT_NEAR(down[2], 0.12 - 1, 1e-12);
    // Yawed 90° left, the optical axis is the car's +y; pitched down, it points below the horizon.
    c.mount.yaw = M_PI / 2;
    auto left = c.to_car({0, 0, 1});
    EXPECT_NEAR(left[0], 0.15, 1e-12);
    EXPECT_NEAR(left[1], 1.02, 1e-12);
    c.mount = {0, 0, 0.3, 0, 0.2};
    auto tilted = c.to_car({0, 0, 1});
    EXPECT_NEAR(tilted[0], std::cos(0.2), 1e-12);
    EXPECT_NEAR(tilted[2], 0.3 - std::sin(0.2), 1e-12);
    // And back.
    auto back = c.to_camera(c.to_car({0.3, -0.2, 1.7}));
    EXPECT_NEAR(back[0], 0.3, 1e-12);
    EXPECT_NEAR(back[1], -0.2, 1e-12);
    EXPECT_NEAR(back[2], 1.7, 1e-12);
}

TEST(ArucoCamera, FileRoundTripAndErrorsNamingTheField)
{
    Camera c = test_camera(0.1);
    c.distortion = {0.01, -0.02, 0.001, 0.002, 0.003};
    const std::string path = temp_file("cam.yaml", "");
    c.save(path);
    Camera back = Camera::load(path);
    EXPECT_EQ(back.width, 640);
    EXPECT_EQ(back.height, 480);
    EXPECT_NEAR(back.fx(), c.fx(), 1e-9);
    EXPECT_NEAR(back.distortion[4], 0.003, 1e-12);
    EXPECT_NEAR(back.mount.pitch, 0.1, 1e-12);
    EXPECT_NEAR(back.mount.y, 0.02, 1e-12);

    EXPECT_EQ(error_of([] { Camera::load("/nonexistent/cam.yaml"); }), "/nonexistent/cam.yaml: cannot open the camera file: no such file");
    const std::string no_mount = temp_file("nomount.yaml",
                                           "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\n"
                                           "camera_matrix: !!opencv-matrix\n  rows: 3\n  cols: 3\n  dt: d\n  data: [500, 0, 320, 0, 500, 240, 0, 0, 1]\n"
                                           "distortion_coefficients: !!opencv-matrix\n  rows: 1\n  cols: 5\n  dt: d\n  data: [0, 0, 0, 0, 0]\n"
                                           "mount_x: 0.1\nmount_y: 0\nmount_z: 0.1\nmount_yaw: 0\n");
    EXPECT_EQ(error_of([&] { Camera::load(no_mount); }), no_mount + ": missing field mount_pitch");
    const std::string short_k = temp_file("shortk.yaml",
                                          "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\n"
                                          "camera_matrix: !!opencv-matrix\n  rows: 2\n  cols: 2\n  dt: d\n  data: [500, 0, 0, 500]\n");
    // Every error at once, each with its line.
    EXPECT_EQ(error_of([&] { Camera::load(short_k); }),
              short_k + ":5: camera_matrix: expected 3×3 values, got 2×2\n" + short_k + ": missing field distortion_coefficients\n" +
                  short_k + ": missing field mount_x\n" + short_k + ": missing field mount_y\n" + short_k + ": missing field mount_z\n" +
                  short_k + ": missing field mount_yaw\n" + short_k + ": missing field mount_pitch");
    const std::string not_yaml = temp_file("garbage.yaml", "this is { not yaml");
    EXPECT_NE(error_of([&] { Camera::load(not_yaml); }).find(not_yaml + ": not an OpenCV FileStorage YAML file"), std::string::npos);
    for (const auto& p : {path, no_mount, short_k, not_yaml}) std::filesystem::remove(p);
}

TEST(ArucoRender, ProjectionRoundTripAtSeveralDistancesAndAngles)
{
    // Render → detect → pose against the renderer's ground truth, car at the origin. From a
    // projected side of 30 px the position is within 1.5 % of the distance (bench/aruco
    // measures how often within the 1 % target); from 20 px markers are found, their position
    // within 5 %.
    const Camera camera = test_camera();
    int checked = 0, precise = 0;
    for (double distance : {0.5, 1.0, 2.0, 3.0}) {
        for (double turn_deg : {-45.0, -20.0, 0.0, 30.0, 50.0}) {
            for (double lateral : {-0.3, 0.0, 0.25}) {
                const double x = 0.15 + distance, y = 0.02 + lateral * distance / 2;
                const double yaw = M_PI + turn_deg * M_PI / 180;  // facing the car, turned
                Renderer renderer(one_marker(x, y, yaw), camera);
                std::vector<RenderedMarker> truth;
                cv::Mat frame = renderer.render({0, 0, 0}, &truth);
                ASSERT_EQ(truth.size(), 1u);
                if (!truth[0].whole_in_view) continue;  // partly outside the image: not required
                ++checked;
                MarkerDetector detector(camera, {}, MarkerSizes{0.1, {}});
                auto seen = detector.observe(frame);
                SCOPED_TRACE("distance " + std::to_string(distance) + " turn " + std::to_string(turn_deg) + " lateral " +
                             std::to_string(lateral) + " side " + std::to_string(truth[0].side_px) + " px");
                EXPECT_NEAR(truth[0].yaw, std::remainder(yaw, 2 * M_PI), 1e-9);
                if (truth[0].side_px < 20) continue;
                ASSERT_EQ(seen.size(), 1u);
                EXPECT_EQ(seen[0].id, 7);
                ASSERT_TRUE(seen[0].has_pose);
                const bool large = truth[0].side_px >= 30;
                precise += large;
                const double tolerance = (large ? 0.015 : 0.05) * distance;
                double corner_error = 0;
                for (int k = 0; k < 4; ++k) corner_error = std::max(corner_error, double(cv::norm(seen[0].corners[k] - truth[0].corners[k])));
                EXPECT_LT(corner_error, large ? 0.5 : 1.5);
                // The car-frame centre is the world one (the car stands at the origin).
                EXPECT_NEAR(seen[0].x, x, tolerance);
                EXPECT_NEAR(seen[0].y, y, tolerance);
                EXPECT_NEAR(seen[0].z, 0.12, tolerance);
                EXPECT_NEAR(seen[0].distance, truth[0].distance, tolerance);
                // A single marker's facing is the noisy part of its pose (gates take their
                // direction from two markers' positions); it never looks away from the camera.
                EXPECT_LT(std::abs(std::remainder(seen[0].yaw - yaw, 2 * M_PI)), (large ? 8 : 60) * M_PI / 180);
            }
        }
    }
    EXPECT_GE(checked, 40);
    EXPECT_GE(precise, 25);
}

TEST(ArucoRender, TheCarsPoseAndTheMountPitchAreAccountedFor)
{
    // The same marker seen from a car turned and moved, with the camera pitched down: the pose
    // in the car frame is the world pose seen from the car.
    const Camera camera = test_camera(0.15);
    const vehicle::World world = one_marker(3.0, 2.0, -M_PI / 2 - 0.2, 0.12, 0.05);
    const vehicle::Pose car{2.6, 0.4, 1.35};
    Renderer renderer(world, camera);
    std::vector<RenderedMarker> truth;
    cv::Mat frame = renderer.render(car, &truth);
    ASSERT_EQ(truth.size(), 1u);
    MarkerDetector detector(camera, {}, MarkerSizes{0.12, {}});
    auto seen = detector.observe(frame);
    ASSERT_EQ(seen.size(), 1u);
    const double dx = 3.0 - car.x, dy = 2.0 - car.y;
    const double want_x = std::cos(car.yaw) * dx + std::sin(car.yaw) * dy, want_y = -std::sin(car.yaw) * dx + std::cos(car.yaw) * dy;
    EXPECT_NEAR(seen[0].x, want_x, 0.015);
    EXPECT_NEAR(seen[0].y, want_y, 0.015);
    EXPECT_NEAR(seen[0].z, 0.05, 0.015);
    EXPECT_LT(std::abs(std::remainder(seen[0].yaw - (-M_PI / 2 - 0.2 - car.yaw), 2 * M_PI)), 8 * M_PI / 180);
}

TEST(ArucoRender, MarkersBehindFacingAwayOrBehindAWallAreNotDrawn)
{
    const Camera camera = test_camera();
    MarkerDetector detector(camera, {}, MarkerSizes{0.1, {}});
    std::vector<RenderedMarker> truth;
    // Behind the car.
    Renderer behind(one_marker(-1.5, 0, 0), camera);
    EXPECT_TRUE(detector.observe(behind.render({0, 0, 0}, &truth)).empty());
    EXPECT_TRUE(truth.empty());
    // In front, but facing away from the car (its back is blank).
    Renderer away(one_marker(1.5, 0, 0), camera);
    EXPECT_TRUE(detector.observe(away.render({0, 0, 0}, &truth)).empty());
    EXPECT_TRUE(truth.empty());
    // Facing the car, hidden behind a wall between them; without the wall it is seen.
    vehicle::World hidden({{1.0, -1.0, 1.0, 1.0}}, {{7, 1.5, 0, M_PI, 0.1, 0.12}});
    Renderer occluded(hidden, camera);
    EXPECT_TRUE(detector.observe(occluded.render({0, 0, 0}, &truth)).empty());
    EXPECT_TRUE(truth.empty());
    Renderer visible(one_marker(1.5, 0, M_PI), camera);
    EXPECT_EQ(detector.observe(visible.render({0, 0, 0}, &truth)).size(), 1u);
    EXPECT_EQ(truth.size(), 1u);
    // A marker on the wall itself (its face on the corridor side) is not hidden by that wall.
    vehicle::World on_wall({{2.0, -1.0, 2.0, 1.0}}, {{7, 2.0, 0.1, M_PI, 0.1, 0.12}});
    Renderer on(on_wall, camera);
    EXPECT_EQ(detector.observe(on.render({0, 0, 0}, &truth)).size(), 1u);
}

TEST(ArucoDetect, FramesWithoutMarkersGiveNothing)
{
    const Camera camera = test_camera();
    MarkerDetector detector(camera, {}, MarkerSizes{0.1, {}});
    vehicle::World walls({{2, -1, 2, 1}}, {});
    for (uint32_t seed = 1; seed <= 50; ++seed) {
        Renderer renderer(walls, camera, RenderOptions{.noise_sigma = 6, .blur = 3, .seed = seed});
        cv::Mat frame = renderer.render({0, 0, 0.1 * seed});
        // Clutter: random dark and light rectangles (squares among them).
        cv::RNG rng(seed);
        for (int k = 0; k < 12; ++k) {
            cv::Rect r(rng.uniform(0, 600), rng.uniform(0, 440), rng.uniform(8, 120), rng.uniform(8, 120));
            cv::rectangle(frame, r, cv::Scalar(rng.uniform(0, 2) * 255), cv::FILLED);
        }
        EXPECT_TRUE(detector.observe(frame).empty()) << "seed " << seed;
    }
}

TEST(ArucoDetect, UnknownSizeMeansNoPoseAndUnknownDictionaryIsNamed)
{
    const Camera camera = test_camera();
    Renderer renderer(one_marker(1.5, 0, M_PI), camera);
    MarkerDetector no_size(camera);
    auto seen = no_size.observe(renderer.render({0, 0, 0}));
    ASSERT_EQ(seen.size(), 1u);
    EXPECT_FALSE(seen[0].has_pose);
    EXPECT_EQ(error_of([&] { MarkerDetector(camera, DetectorOptions{.dictionary = "DICT_9X9_1"}); }).substr(0, 47),
              "unknown dictionary 'DICT_9X9_1' (known: DICT_4X");
    EXPECT_EQ(error_of([&] { Renderer(one_marker(1, 0, M_PI, 0.1, 0.12, 77), camera); }),
              "the map: marker id 77 is not in DICT_4X4_50 (ids 0..49)");
}
