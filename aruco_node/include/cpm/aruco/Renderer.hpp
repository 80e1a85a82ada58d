#pragma once
#include <cpm/aruco/Camera.hpp>
#include <cpm/aruco/Images.hpp>
#include <cpm/vehicle/VehicleModel.hpp>
#include <cpm/vehicle/World.hpp>

#include <opencv2/core.hpp>

#include <array>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace cpm::aruco {

/// How the synthetic camera's images look.
struct RenderOptions
{
    std::string dictionary = "DICT_4X4_50";
    double noise_sigma = 0;  ///< Gaussian noise, grey levels (of 255), drawn anew each frame
    int blur = 0;            ///< box blur kernel side, px (0 or 1: none)
    uint32_t seed = 1;       ///< of the noise
    uint8_t wall_grey = 150, floor_grey = 95;
};

/// A marker in a rendered frame, as it truly is.
struct RenderedMarker
{
    int id = 0;
    std::array<cv::Point2f, 4> corners;  ///< px, the black square's corners in the detector's order
    double x = 0, y = 0, z = 0, yaw = 0; ///< centre and facing in the car frame (m, rad)
    double distance = 0;                 ///< camera to centre, m
    double side_px = 0;                  ///< mean projected side of the black square
    double shortest_side_px = 0;         ///< its most foreshortened side (what limits detection)
    bool whole_in_view = false;          ///< all four corners at least 3 px inside the image
};

/// The synthetic camera: what the car's camera sees of the world's markers from a true pose.
/// Each marker (its white quiet zone of one cell included) is projected through the pinhole
/// model and warped onto a plain wall/floor background, far ones first; markers behind the
/// camera, facing away or hidden by a wall are left out. Deterministic for a seed. Lens
/// distortion is not rendered (the homography is exact only for a pinhole): render with an
/// undistorted camera.
class Renderer
{
public:
    /// Throws cpm::Error naming an unknown dictionary.
    Renderer(vehicle::World world, Camera camera, RenderOptions options = {});
    ~Renderer();

    /// One mono8 frame of the camera's size from the car's pose (rear axle, world frame);
    /// `truth` (if given) receives every marker drawn.
    cv::Mat render(const vehicle::Pose& car, std::vector<RenderedMarker>* truth = nullptr);
    void render(const vehicle::Pose& car, cv::Mat& frame, std::vector<RenderedMarker>* truth = nullptr);

    const Camera& camera() const { return camera_; }
    const vehicle::World& world() const { return world_; }

private:
    struct Impl;
    vehicle::World world_;
    Camera camera_;
    RenderOptions options_;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm::aruco
