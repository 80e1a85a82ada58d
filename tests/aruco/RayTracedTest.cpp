// Perception on ray-traced frames: POV-Ray (Debian's povray) renders marker cards (OpenCV's own
// marker images as image maps) above a checkered floor before a wall, lit by an area light
// whose soft shadows fall across them, half of them crossed by a post's shadow band, seen by a perspective
// camera whose projection is the ideal pinhole of the same field of view (POV-Ray samples each
// pixel at its centre: a vertical edge at x = 0 falls between columns 319 and 320 of 640). The
// ground truth comes from the scene this test writes (each card's corners and place), not from
// cpm's renderer. Held to the detector's targets on its own frames: from a projected side of
// 30 px found, corners within 1 px, position within 1.5 % of the distance; from 20 px found
// and within 5 %. The same renders with sensor noise added are held to the same targets.
#include <cpm/aruco/Camera.hpp>
#include <cpm/aruco/Detector.hpp>

#include <cpm_test/TempDir.hpp>

#include <gtest/gtest.h>

#include <opencv2/aruco.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>
#include <vector>

using namespace cpm::aruco;

namespace {

/// One marker card in the scene: the marker of `id`, black square of side `size`, centre `c`
/// (car frame), its face looking along `yaw`; optionally a pole whose shadow crosses the card
/// `shadow_at` marker sides right of its centre.
struct Card
{
    int id = 0;
    double size = 0.1;
    cv::Vec3d c;
    double yaw = M_PI;
    bool shadowed = false;
    double shadow_at = 0;

    cv::Vec3d normal() const { return {std::cos(yaw), std::sin(yaw), 0}; }
    cv::Vec3d right() const { return {-std::sin(yaw), std::cos(yaw), 0}; }  // as seen from in front
    /// The point u, v marker sides right of and above the centre.
    cv::Vec3d at(double u, double v) const { return c + right() * (u * size) + cv::Vec3d(0, 0, 1) * (v * size); }
};

/// Car frame (x forward, y left, z up; right-handed) into POV-Ray's (x right, y up, z forward;
/// left-handed).
cv::Vec3d pov(const cv::Vec3d& car) { return {-car[1], car[2], car[0]}; }

std::string vec(const cv::Vec3d& v)
{
    std::ostringstream out;
    out.precision(9);
    out << '<' << v[0] << ',' << v[1] << ',' << v[2] << '>';
    return out.str();
}

const cv::Vec3d light_position(-1.0, 1.6, 2.6);  // car frame: behind the camera, left, high

/// Where the post that shadows `card` stands (its foot, POV-Ray's frame) and which way its 6 cm
/// face turns: a sixth of the way from the card's shadowed line towards the light, facing it,
/// so its shadow is a soft vertical band across the card.
std::pair<cv::Vec3d, cv::Vec3d> shadow_caster(const Card& card)
{
    const cv::Vec3d q = card.at(card.shadow_at, 0);
    const cv::Vec3d foot(q[0] + (light_position[0] - q[0]) / 6, q[1] + (light_position[1] - q[1]) / 6, 0);
    cv::Vec3d towards_light = pov(cv::Vec3d(light_position[0] - foot[0], light_position[1] - foot[1], 0));
    towards_light /= cv::norm(towards_light);
    return {pov(foot), cv::Vec3d(towards_light[2], 0, -towards_light[0])};
}

/// The scene: camera at the mount looking along the car's x axis, `cards` with their images
/// "card<id>.png" beside the file.
std::string scene_text(const Camera& camera, const std::vector<Card>& cards)
{
    std::ostringstream s;
    s.precision(9);
    const double fov_deg = 2 * std::atan(camera.width / 2.0 / camera.fx()) * 180 / M_PI;
    const cv::Vec3d eye(camera.mount.x, camera.mount.y, camera.mount.z);
    s << "#version 3.7;\nglobal_settings { assumed_gamma 1.0 }\n"
      << "camera { perspective location " << vec(pov(eye)) << " direction <0,0,1> right x*" << camera.width << "/" << camera.height
      << " up y angle " << fov_deg << " }\n"
      // A soft area light (its shadows have a penumbra) and a weak fill, as in a room.
      << "light_source { " << vec(pov(light_position)) << " color rgb 1.1 area_light <0.2,0,0>, <0,0,0.2>, 5, 5 adaptive 1 circular orient }\n"
      << "light_source { <0,3,-2> color rgb 0.25 shadowless }\n"
      << "plane { y, 0 pigment { checker color rgb 0.35 color rgb 0.5 scale 0.5 } finish { ambient 0.1 diffuse 0.7 } }\n"
      << "plane { z, 6 pigment { gradient x color_map { [0 color rgb 0.45] [1 color rgb 0.7] } scale 8 translate -4*x } finish { ambient 0.1 "
         "diffuse 0.7 } }\n";
    for (const auto& card : cards) {
        // The card (twice the marker's side) as POV-Ray's unit square carrying the image map,
        // moved by a matrix whose rows are where its x, y and z axes go.
        const cv::Vec3d corner = pov(card.at(-1, -1)), x_axis = pov(card.right() * (2 * card.size)),
                        y_axis = pov(cv::Vec3d(0, 0, 2 * card.size)), z_axis = pov(-card.normal());
        s << "polygon { 5, <0,0>, <1,0>, <1,1>, <0,1>, <0,0> pigment { image_map { png \"card" << card.id
          << ".png\" interpolate 2 once } } finish { ambient 0.12 diffuse 0.8 } matrix <";
        const char* separator = "";
        for (const auto& row : {x_axis, y_axis, z_axis, corner}) {
            s << separator << row[0] << ',' << row[1] << ',' << row[2];
            separator = ", ";
        }
        s << "> }\n";
        if (card.shadowed) {
            const auto [foot, across] = shadow_caster(card);
            s << "box { <-0.03,0,-0.01>, <0.03,1.2,0.01> pigment { color rgb 0.6 } finish { ambient 0.1 diffuse 0.7 } matrix <"
              << across[0] << ',' << across[1] << ',' << across[2] << ", 0,1,0, " << -across[2] << ",0," << across[0] << ", " << foot[0]
              << ',' << foot[1] << ',' << foot[2] << "> }\n";
        }
    }
    return s.str();
}

/// The card image: the marker, 240 px, on white, 480 px in all.
cv::Mat card_image(int id)
{
    cv::Mat marker, card(480, 480, CV_8UC1, cv::Scalar(255));
    cv::aruco::drawMarker(cv::aruco::getPredefinedDictionary(cv::aruco::DICT_4X4_50), id, 240, marker, 1);
    marker.copyTo(card(cv::Rect(120, 120, 240, 240)));
    return card;
}

/// Renders the scene with POV-Ray into a gray image; fails the test naming POV-Ray's words.
cv::Mat render(const cpm_test::TempDir& dir, const Camera& camera, const std::vector<Card>& cards, const std::string& name)
{
    for (const auto& card : cards) cv::imwrite(dir.file("card" + std::to_string(card.id) + ".png"), card_image(card.id));
    dir.write(name + ".pov", scene_text(camera, cards));
    // POV-Ray reads image maps only from its working folder (its file I/O security).
    const std::string command = "cd '" + dir.path.string() + "' && povray +I" + name + ".pov +O" + name + ".png +FN +W" +
                                std::to_string(camera.width) + " +H" + std::to_string(camera.height) +
                                " -D +A0.1 +AM2 +R3 -V +WT2 >" + name + ".log 2>&1";
    const int status = std::system(command.c_str());
    EXPECT_EQ(status, 0) << command << ":\n" << dir.read(name + ".log");
    cv::Mat frame = cv::imread(dir.file(name + ".png"), cv::IMREAD_GRAYSCALE);
    EXPECT_FALSE(frame.empty()) << "POV-Ray wrote no image: " << dir.read(name + ".log");
    return frame;
}

cv::Point2f project(const Camera& camera, const cv::Vec3d& car)
{
    const cv::Vec3d p = camera.to_camera(car);
    return {float(camera.fx() * p[0] / p[2] + camera.camera_matrix(0, 2)), float(camera.fy() * p[1] / p[2] + camera.camera_matrix(1, 2))};
}

struct Tally
{
    int checked = 0, precise = 0, shadowed = 0;
    double worst_corner_px = 0, worst_position_share = 0;
};

/// Holds the detector to its targets on one frame of `cards`.
void judge(const Camera& camera, const cv::Mat& frame, const std::vector<Card>& cards, const std::string& look, Tally& tally)
{
    MarkerDetector detector(camera, {}, MarkerSizes{0.1, {}});
    const auto seen = detector.observe(frame);
    for (const auto& card : cards) {
        const std::array<cv::Point2f, 4> truth{project(camera, card.at(-0.5, 0.5)), project(camera, card.at(0.5, 0.5)),
                                               project(camera, card.at(0.5, -0.5)), project(camera, card.at(-0.5, -0.5))};
        double side_px = 1e9;
        for (int k = 0; k < 4; ++k) side_px = std::min(side_px, double(cv::norm(truth[k] - truth[(k + 1) % 4])));
        const double distance = cv::norm(camera.to_camera(card.c));
        SCOPED_TRACE(look + ": marker " + std::to_string(card.id) + " at " + std::to_string(card.c[0]) + ", " + std::to_string(card.c[1]) +
                     " facing " + std::to_string(card.yaw * 180 / M_PI) + " deg" + (card.shadowed ? ", a shadow across it" : "") + ", side " +
                     std::to_string(side_px) + " px");
        ASSERT_GE(side_px, 20.0) << "the scene puts a marker below the size the detector is held to";
        for (const auto& other : cards) {  // no post stands before a marker
            if (!other.shadowed) continue;
            const auto [foot, across] = shadow_caster(other);
            const cv::Vec3d foot_car(foot[2], -foot[0], card.c[2]), across_car(across[2], -across[0], 0);
            const float a = project(camera, foot_car - across_car * 0.03).x, b = project(camera, foot_car + across_car * 0.03).x;
            float left = 1e9f, right = -1e9f;
            for (const auto& p : truth) left = std::min(left, p.x), right = std::max(right, p.x);
            const bool behind = camera.to_camera(foot_car)[2] > camera.to_camera(card.c)[2] + 0.12;
            ASSERT_TRUE(behind || std::max(a, b) < left - 3 || std::min(a, b) > right + 3) << "the post of marker " << other.id << " hides it";
        }
        const MarkerObservation* found = nullptr;
        for (const auto& o : seen) found = o.id == card.id ? &o : found;
        ++tally.checked;
        tally.shadowed += card.shadowed;
        ASSERT_NE(found, nullptr) << "not found";
        ASSERT_TRUE(found->has_pose);
        const bool large = side_px >= 30;
        tally.precise += large;
        double corner_error = 0;
        for (int k = 0; k < 4; ++k) corner_error = std::max(corner_error, double(cv::norm(found->corners[k] - truth[k])));
        EXPECT_LT(corner_error, large ? 1.0 : 2.0);
        const double position_error = cv::norm(cv::Vec3d(found->x, found->y, found->z) - card.c);
        EXPECT_LT(position_error, (large ? 0.015 : 0.05) * distance);
        EXPECT_NEAR(found->distance, distance, (large ? 0.015 : 0.05) * distance);
        tally.worst_corner_px = std::max(tally.worst_corner_px, corner_error);
        tally.worst_position_share = std::max(tally.worst_position_share, position_error / distance);
    }
}

}  // namespace

TEST(ArucoRayTraced, MarkersInARayTracedRoomWithSoftShadowsAreFoundAndPlaced)
{
    const Camera camera = Camera::ideal(640, 480, 70 * M_PI / 180, CameraMount{0.15, 0.02, 0.12, 0, 0});
    // Each frame: three cards, the nearest on the sides so none hides another.
    struct Place
    {
        double distance, lateral_tan, turn_deg;
        bool shadowed;
        double shadow_at;
    };
    const std::vector<std::array<Place, 3>> frames{
        {{{0.6, -0.35, 0, true, 0}, {1.2, 0.0, 25, true, 0.0}, {0.8, 0.33, -30, false, 0}}},
        {{{1.0, -0.3, 40, true, 0.3}, {1.7, 0.02, 0, false, 0}, {1.4, 0.28, -15, false, 0}}},
        {{{1.5, -0.25, -35, false, 0}, {1.8, 0.05, 15, true, 0.1}, {0.7, 0.36, 10, false, 0.0}}},
        {{{0.6, -0.42, -20, true, -0.3}, {1.3, -0.02, -40, true, 0.2}, {1.2, 0.3, 35, false, 0}}},
    };
    cpm_test::TempDir dir;
    Tally tally;
    int frame_number = 0, id = 1;
    for (const auto& places : frames) {
        std::vector<Card> cards;
        for (const auto& p : places) {
            Card card;
            card.id = id++;
            card.c = cv::Vec3d(0.15 + p.distance, 0.02 - p.lateral_tan * p.distance, 0.12);
            card.yaw = M_PI + p.turn_deg * M_PI / 180;
            card.shadowed = p.shadowed;
            card.shadow_at = p.shadow_at;
            cards.push_back(card);
        }
        const std::string name = "frame" + std::to_string(frame_number++);
        const cv::Mat frame = render(dir, camera, cards, name);
        ASSERT_FALSE(frame.empty());
        judge(camera, frame, cards, name + " as rendered", tally);
        // The same light through a sensor: Gaussian noise, sigma 6 of 255.
        cv::Mat noisy, noise(frame.size(), CV_16S);
        cv::RNG(uint64_t(frame_number)).fill(noise, cv::RNG::NORMAL, 0, 6);
        cv::Mat wide;
        frame.convertTo(wide, CV_16S);
        wide += noise;
        wide.convertTo(noisy, CV_8U);  // saturating
        judge(camera, noisy, cards, name + " with noise", tally);
    }
    EXPECT_EQ(tally.checked, 24);
    EXPECT_GE(tally.shadowed, 10);
    std::printf("ray-traced frames: %d markers checked (%d of 30 px or more, %d under a shadow band); worst corner %.2f px, worst position "
                "%.2f %% of the distance\n",
                tally.checked, tally.precise, tally.shadowed, tally.worst_corner_px, 100 * tally.worst_position_share);
}
