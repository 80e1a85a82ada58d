#pragma once
#include <opencv2/core.hpp>

#include <optional>
#include <string>

/// The perception half of the lab: camera model, marker detection and pose, the synthetic
/// camera, calibration, and the aruco_node / camera_sim programs' work (docs/design.md).
namespace cpm::aruco {

/// Where the camera sits on the car. Car frame: x forward, y left, z up from the ground,
/// metres; yaw turns the camera left, pitch tilts it down (radians).
struct CameraMount
{
    double x = 0, y = 0, z = 0.1, yaw = 0, pitch = 0;
};

/// Where an overhead camera hangs in the map (`cpm camera locate` finds it from floor markers).
struct OverheadPose
{
    cv::Vec3d position{0, 0, 0};              ///< the optical centre in the map, metres (world_x, world_y, world_z)
    cv::Matx33d rotation = cv::Matx33d::eye(); ///< camera-to-map: a camera-frame vector into the map frame (world_rotation)
    double residual_px = -1;                   ///< the floor markers' reprojection residual when located (RMS, px); -1 unknown

    /// The map point p in the camera frame.
    cv::Vec3d to_camera(const cv::Vec3d& p_map) const { return rotation.t() * (p_map - position); }
};

/// What a camera file must say besides the lens.
enum class CameraPlacement
{
    on_car,    ///< the mount on the car (mount_*), as the cars' cameras
    overhead,  ///< the pose in the map (world_*), as the positioning camera under the ceiling
    lens_only, ///< neither (a camera about to be located); either is read when present
};

/// A pinhole camera with OpenCV's distortion model and its mounting on the car. Camera frame
/// (OpenCV): x right, y down, z along the optical axis.
struct Camera
{
    int width = 640, height = 480;
    cv::Matx33d camera_matrix = cv::Matx33d::eye();
    cv::Vec<double, 5> distortion{0, 0, 0, 0, 0};
    CameraMount mount;
    /// An overhead camera's pose in the map (world_x, world_y, world_z, world_rotation).
    std::optional<OverheadPose> overhead;

    /// Reads a camera file (OpenCV FileStorage YAML: image_width, image_height, camera_matrix
    /// 3×3, distortion_coefficients 1×5; on a car mount_x, mount_y, mount_z, mount_yaw,
    /// mount_pitch; overhead world_x, world_y, world_z, world_rotation 3×3 and optionally
    /// world_residual_px). Throws cpm::Error naming the file and the missing or wrong field.
    static Camera load(const std::string& path, CameraPlacement placement = CameraPlacement::on_car);
    /// Writes the same format (the mount unless the camera is overhead).
    void save(const std::string& path) const;

    /// An ideal camera (no distortion, principal point at the centre) with this horizontal
    /// field of view, radians.
    static Camera ideal(int width, int height, double horizontal_fov, CameraMount mount = {});

    /// Empty when an image of width × height px is this camera's; else what disagrees:
    /// "320×240 px, the camera file says 640×480".
    std::string size_mismatch(int image_width, int image_height) const;

    double fx() const { return camera_matrix(0, 0); }
    double fy() const { return camera_matrix(1, 1); }

    /// Rotation taking camera-frame vectors into the car frame.
    cv::Matx33d car_from_camera_rotation() const;
    /// A point in the camera frame, expressed in the car frame (and back).
    cv::Vec3d to_car(const cv::Vec3d& p_camera) const;
    cv::Vec3d to_camera(const cv::Vec3d& p_car) const;
};

}  // namespace cpm::aruco
