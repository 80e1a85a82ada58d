// Perception from frames cpm did not draw: OpenCV's own marker images (cv::aruco::drawMarker),
// set into a scene with cv::warpPerspective through a pinhole camera at a known pose, under a
// lighting gradient, sensor noise and blur. The ground truth comes from this generator (the
// projected corners, the marker's place), not from cpm's renderer; the detector's targets are
// those it is held to on its own frames (from a projected side of 30 px the position within
// 1.5 % of the distance, from 20 px found and within 5 %); where they do not hold here, the
// test says so and by how much.
#include <cpm/aruco/Camera.hpp>
#include <cpm/aruco/Detector.hpp>

#include <gtest/gtest.h>

#include <opencv2/aruco.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <cstdio>
#include <string>

using namespace cpm::aruco;

namespace {

struct Scene
{
    cv::Mat frame;                      // 8-bit gray
    std::array<cv::Point2f, 4> corners; // the black square's, clockwise from its top-left
    double side_px = 0;                 // its shortest projected side
    bool in_view = false;
};

enum class Look { clean, shadowed_and_noisy, blurred_and_noisy };

/// Marker `id` (DICT_4X4_50) of side `size` m, centre `c` (car frame), facing `yaw`, seen by
/// `camera`; the marker sits on a white card twice its side, the card on a gray gradient.
Scene scene(const Camera& camera, int id, double size, cv::Vec3d c, double yaw, Look look, uint64_t seed)
{
    const auto dictionary = cv::aruco::getPredefinedDictionary(cv::aruco::DICT_4X4_50);
    const int side = 240, margin = side / 2;
    cv::Mat marker;
    cv::aruco::drawMarker(dictionary, id, side, marker, 1);
    cv::Mat card(side + 2 * margin, side + 2 * margin, CV_8UC1, cv::Scalar(255));
    marker.copyTo(card(cv::Rect(margin, margin, side, side)));

    // The card's corners in the car frame: seen from in front (looking along -normal), right and up.
    const cv::Vec3d normal(std::cos(yaw), std::sin(yaw), 0), right(-normal[1], normal[0], 0), up(0, 0, 1);
    auto project = [&](double u, double v) {  // u right, v up, in marker sides from the centre
        const cv::Vec3d p = camera.to_camera(c + right * (u * size) + up * (v * size));
        const auto& k = camera.camera_matrix;
        return cv::Point2f(float(k(0, 0) * p[0] / p[2] + k(0, 2)), float(k(1, 1) * p[1] / p[2] + k(1, 2)));
    };
    Scene s;
    s.corners = {project(-0.5, 0.5), project(0.5, 0.5), project(0.5, -0.5), project(-0.5, -0.5)};
    const double card_half = 0.5 * double(side + 2 * margin) / side;
    const std::array<cv::Point2f, 4> card_corners{project(-card_half, card_half), project(card_half, card_half), project(card_half, -card_half),
                                                  project(-card_half, -card_half)};
    const cv::Point2f card_image[4] = {{0, 0}, {float(card.cols), 0}, {float(card.cols), float(card.rows)}, {0, float(card.rows)}};
    const cv::Mat h = cv::getPerspectiveTransform(card_image, card_corners.data());

    // A gray wall, darker to the left; the card warped onto it.
    s.frame = cv::Mat(camera.height, camera.width, CV_8UC1);
    for (int x = 0; x < s.frame.cols; ++x) s.frame.col(x).setTo(cv::Scalar(90 + 80.0 * x / s.frame.cols));
    cv::warpPerspective(card, s.frame, h, s.frame.size(), cv::INTER_LINEAR, cv::BORDER_TRANSPARENT);

    cv::RNG rng(seed);
    if (look != Look::clean) {
        cv::Mat f;
        s.frame.convertTo(f, CV_32F);
        if (look == Look::shadowed_and_noisy) {  // light falling off across the image, 1.1 to 0.45
            for (int x = 0; x < f.cols; ++x) f.col(x) *= 1.1 - 0.65 * x / f.cols;
        } else {
            cv::GaussianBlur(f, f, cv::Size(5, 5), 1.0);
        }
        cv::Mat noise(f.size(), CV_32F);
        rng.fill(noise, cv::RNG::NORMAL, 0, 6);
        f += noise;
        f.convertTo(s.frame, CV_8U);  // saturating
    }
    s.side_px = 1e9;
    s.in_view = true;
    for (int k = 0; k < 4; ++k) {
        s.side_px = std::min(s.side_px, double(cv::norm(s.corners[k] - s.corners[(k + 1) % 4])));
        s.in_view = s.in_view && card_corners[k].x >= 0 && card_corners[k].y >= 0 && card_corners[k].x < float(camera.width) &&
                    card_corners[k].y < float(camera.height);
    }
    return s;
}

const char* name(Look l) { return l == Look::clean ? "clean" : l == Look::shadowed_and_noisy ? "shadowed and noisy" : "blurred and noisy"; }

}  // namespace

TEST(ArucoForeignFrames, OpenCvsOwnMarkersWarpedUnderShadowNoiseAndBlurAreFoundAndPlaced)
{
    // What holds on these frames, and where they differ from cpm's own (measured 2026-12-04):
    // - from 30 px every marker is found, its corners within 1 px, its position within 1.5 %;
    // - from 20 px found and within 5 %, except under blur and noise, where one marker of 23 px
    //   at 2 m is missed: there the detection holds from 25 px;
    // - a single marker's facing is within 10 degrees from 30 px, except that IPPE's two
    //   solutions for a square swap now and then (one case of 45 px, 23 degrees off, in every
    //   look): at most 1 in 20 beyond 10 degrees, none beyond 30.
    const Camera camera = Camera::ideal(640, 480, 70 * M_PI / 180, CameraMount{0.15, 0.02, 0.12, 0, 0});
    int checked = 0, precise = 0, facing_off = 0;
    uint64_t seed = 1;
    for (Look look : {Look::clean, Look::shadowed_and_noisy, Look::blurred_and_noisy}) {
        for (double distance : {0.5, 1.0, 2.0, 3.0}) {
            for (double turn_deg : {-45.0, -20.0, 0.0, 30.0, 50.0}) {
                for (double lateral : {-0.3, 0.0, 0.25}) {
                    const cv::Vec3d c(0.15 + distance, 0.02 + lateral * distance / 2, 0.12);
                    const double yaw = M_PI + turn_deg * M_PI / 180;  // facing the car, turned
                    const Scene s = scene(camera, 7, 0.1, c, yaw, look, seed++);
                    const double must_find_from = look == Look::blurred_and_noisy ? 25 : 20;
                    if (!s.in_view || s.side_px < must_find_from) continue;
                    ++checked;
                    SCOPED_TRACE(std::string(name(look)) + ": distance " + std::to_string(distance) + " turn " + std::to_string(turn_deg) +
                                 " lateral " + std::to_string(lateral) + " side " + std::to_string(s.side_px) + " px");
                    MarkerDetector detector(camera, {}, MarkerSizes{0.1, {}});
                    const auto seen = detector.observe(s.frame);
                    ASSERT_EQ(seen.size(), 1u);
                    EXPECT_EQ(seen[0].id, 7);
                    ASSERT_TRUE(seen[0].has_pose);
                    const bool large = s.side_px >= 30;
                    precise += large;
                    const double tolerance = (large ? 0.015 : 0.05) * distance, true_distance = cv::norm(camera.to_camera(c));
                    double corner_error = 0;
                    for (int k = 0; k < 4; ++k) corner_error = std::max(corner_error, double(cv::norm(seen[0].corners[k] - s.corners[k])));
                    EXPECT_LT(corner_error, large ? 1.0 : 2.0);
                    EXPECT_NEAR(seen[0].x, c[0], tolerance);
                    EXPECT_NEAR(seen[0].y, c[1], tolerance);
                    EXPECT_NEAR(seen[0].z, c[2], tolerance);
                    EXPECT_NEAR(seen[0].distance, true_distance, tolerance);
                    const double facing_error = std::abs(std::remainder(seen[0].yaw - yaw, 2 * M_PI));
                    if (large) {
                        facing_off += facing_error > 10 * M_PI / 180;
                        EXPECT_LT(facing_error, 30 * M_PI / 180);
                    } else {
                        EXPECT_LT(facing_error, 60 * M_PI / 180);
                    }
                }
            }
        }
    }
    EXPECT_GE(checked, 100);
    EXPECT_GE(precise, 75);
    EXPECT_LE(facing_off * 20, precise) << facing_off << " of " << precise << " markers of 30 px or more faced over 10 degrees off";
    std::printf("foreign frames: %d markers checked, %d of 30 px or more (%d faced over 10 degrees off)\n", checked, precise, facing_off);
}

TEST(ArucoForeignFrames, AnotherDictionarysMarkerAndAPlainCardGiveNothing)
{
    const Camera camera = Camera::ideal(640, 480, 70 * M_PI / 180, CameraMount{0.15, 0.02, 0.12, 0, 0});
    // A 5x5 marker (not DICT_4X4_50) where the 4x4 one would be: no false find.
    cv::Mat other;
    cv::aruco::drawMarker(cv::aruco::getPredefinedDictionary(cv::aruco::DICT_5X5_50), 7, 200, other, 1);
    cv::Mat frame(480, 640, CV_8UC1, cv::Scalar(200));
    other.copyTo(frame(cv::Rect(220, 140, 200, 200)));
    MarkerDetector detector(camera, {}, MarkerSizes{0.1, {}});
    EXPECT_TRUE(detector.observe(frame).empty());
    cv::Mat card(480, 640, CV_8UC1, cv::Scalar(200));
    cv::rectangle(card, cv::Rect(220, 140, 200, 200), cv::Scalar(0), cv::FILLED);  // a black square, no bits
    EXPECT_TRUE(detector.observe(card).empty());
}
