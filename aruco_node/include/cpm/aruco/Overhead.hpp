#pragma once
// The lab's positioning system (IPS): an overhead camera under the ceiling that sees a marker on
// every car's roof. Its place in the map comes from markers on the floor (locate_camera); each
// frame then gives every car's pose (OverheadLocator). OverheadRenderer draws such frames for
// simulated cars.
#include <cpm/aruco/Camera.hpp>
#include <cpm/aruco/Detector.hpp>
#include <cpm/aruco/Renderer.hpp>
#include <cpm/vehicle/VehicleModel.hpp>
#include <cpm/vehicle/World.hpp>

#include <opencv2/core.hpp>

#include <array>
#include <memory>
#include <string>
#include <vector>

namespace cpm::aruco {

/// A car as the overhead camera sees it: its id and pose (the point its roof marker is centred
/// over, map frame).
struct OverheadCar
{
    int vehicle_id = 0;
    vehicle::Pose pose;
};

/// A marker in a rendered overhead frame, as it truly is.
struct OverheadTruth
{
    int id = 0;
    int vehicle_id = 0;                   ///< the car it is on; 0 for a floor marker
    std::array<cv::Point2f, 4> corners;   ///< px, the black square's corners in the detector's order
    double side_px = 0;                   ///< mean projected side
    bool whole_in_view = false;           ///< all four corners at least 3 px inside the image
};

/// The synthetic overhead camera: the floor (with its floor markers) and every car's body and
/// roof marker seen from the camera's pose in the map (the camera file's world_*), through its
/// lens distortion (drawn through a pinhole, then remapped). Deterministic for a seed.
class OverheadRenderer
{
public:
    /// `camera` must have its overhead pose. Throws cpm::Error naming a marker id the dictionary
    /// does not have, or the missing pose.
    OverheadRenderer(vehicle::World world, Camera camera, RenderOptions options = {}, vehicle::VehicleParameters body = {});
    ~OverheadRenderer();
    OverheadRenderer(const OverheadRenderer&) = delete;
    OverheadRenderer& operator=(const OverheadRenderer&) = delete;

    /// One mono8 frame of the camera's size. A car without a roof marker in the world is drawn
    /// without one. `truth` (if given) receives every marker drawn.
    void render(const std::vector<OverheadCar>& cars, cv::Mat& frame, std::vector<OverheadTruth>* truth = nullptr);

    /// Where a map point is in the image (lens distortion included).
    cv::Point2d project(const cv::Vec3d& map_point) const;

    const Camera& camera() const { return camera_; }
    const vehicle::World& world() const { return world_; }

private:
    struct Impl;
    vehicle::World world_;
    Camera camera_;
    std::unique_ptr<Impl> impl_;
};

/// A car found in one overhead frame.
struct LocatedCar
{
    int vehicle_id = 0;
    int marker_id = 0;
    double x = 0, y = 0, yaw = 0;         ///< the roof marker's centre and x axis, map frame (m, rad)
    std::array<cv::Point2f, 4> corners;   ///< px
};

/// What one overhead frame showed.
struct OverheadView
{
    std::vector<LocatedCar> cars;       ///< by vehicle id
    std::vector<int> unknown_ids;       ///< markers on no roof and no floor of the world
    std::vector<int> seen_twice;        ///< roof markers found more than once in the frame (none of them taken)
    std::vector<int> misfits;           ///< roof markers whose size on the roof's plane is off by more than 25 % (not taken)
    int floor_markers = 0;              ///< floor markers seen
    /// RMS distance (px) of the seen floor markers' corners from where the camera's pose puts
    /// them; -1 when none is seen. A camera that moved shows here first.
    double floor_residual_px = -1;
};

/// The IPS's work on one frame: finds the roof markers and intersects their corners' sight lines
/// with the roof's plane (the world's roof_markers z); a car's pose is its marker's centre and
/// x axis. Not thread-safe (one per thread).
class OverheadLocator
{
public:
    /// `camera` must have its overhead pose. Throws cpm::Error naming what is missing.
    OverheadLocator(vehicle::World world, Camera camera, DetectorOptions options = {});
    ~OverheadLocator();
    OverheadLocator(OverheadLocator&&) noexcept;
    OverheadLocator& operator=(OverheadLocator&&) noexcept;

    /// `gray`: 8-bit, one channel, the camera's size.
    OverheadView locate(const cv::Mat& gray) const;

    /// Where the image point (px, distorted) lies on the horizontal plane at height z (map frame).
    cv::Vec3d on_plane(const cv::Point2f& px, double z) const;

    const Camera& camera() const { return camera_; }
    const vehicle::World& world() const { return world_; }

private:
    struct Impl;
    vehicle::World world_;
    Camera camera_;
    std::unique_ptr<Impl> impl_;
};

/// What `cpm camera locate` finds.
struct CameraLocation
{
    OverheadPose pose;          ///< residual_px set
    std::vector<int> markers;   ///< the floor markers it used
    std::vector<int> unknown;   ///< markers seen that are no floor marker
};

/// The overhead camera's pose from the floor markers one image of it shows (their corners at
/// their known map places; solvePnP over all of them, refined by Levenberg-Marquardt). Needs at
/// least 2 floor markers; throws cpm::Error saying which it saw when it cannot.
CameraLocation locate_camera(const Camera& lens, const vehicle::World& world, const cv::Mat& gray, DetectorOptions options = {});

/// The corners of a flat marker of side `size` centred at (x, y, z) whose x axis points along
/// yaw, in the detector's order (top-left, top-right, bottom-right, bottom-left of the printed
/// marker seen from above), map frame.
std::array<cv::Vec3d, 4> flat_marker_corners(double x, double y, double z, double yaw, double size);

/// The angle between two rotations, radians.
double rotation_angle(const cv::Matx33d& a, const cv::Matx33d& b);

}  // namespace cpm::aruco
