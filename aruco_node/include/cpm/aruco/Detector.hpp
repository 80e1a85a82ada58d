#pragma once
#include <cpm/aruco/Camera.hpp>

#include <opencv2/core.hpp>

#include <array>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace cpm::vehicle {
class World;
}

namespace cpm::aruco {

/// How markers are found (OpenCV's defaults otherwise).
struct DetectorOptions
{
    std::string dictionary = "DICT_4X4_50";
    bool subpixel = true;      ///< sub-pixel corners: lines fitted to the marker's edges, met at the corners
    int subpixel_window = 5;   ///< px, the largest window of the fallback (cornerSubPix), half side
    bool aruco3 = false;       ///< OpenCV's multi-scale ArUco3 search
};

/// The side of each marker's black square, metres: by id from a world file, else `fallback`
/// (0: unknown, no pose).
struct MarkerSizes
{
    double fallback = 0;
    std::map<int, double> by_id;

    static MarkerSizes from_world(const vehicle::World& world, double fallback = 0);
    double of(int id) const;
};

/// One marker in one image.
struct MarkerObservation
{
    int id = 0;
    std::array<cv::Point2f, 4> corners;  ///< px, clockwise from the marker's top-left
    bool has_pose = false;               ///< false when the marker's size is unknown
    double x = 0, y = 0, z = 0;          ///< its centre in the car frame, m
    double yaw = 0;                      ///< direction its face looks, car frame, rad
    double distance = 0;                 ///< camera to centre, m
};

/// Detection (cv::aruco, OpenCV 4.6) and pose (solvePnP, IPPE_SQUARE) of the markers in
/// one image, in the car frame through the camera's mounting. Not thread-safe (one per thread).
class MarkerDetector
{
public:
    /// Throws cpm::Error naming an unknown dictionary.
    MarkerDetector(Camera camera, DetectorOptions options = {}, MarkerSizes sizes = {});
    ~MarkerDetector();
    MarkerDetector(MarkerDetector&&) noexcept;
    MarkerDetector& operator=(MarkerDetector&&) noexcept;

    /// Detection only: ids and corners (has_pose false). `gray` is 8-bit, one channel.
    void detect(const cv::Mat& gray, std::vector<MarkerObservation>& out) const;
    /// Detection and the pose of every marker whose size is known.
    std::vector<MarkerObservation> observe(const cv::Mat& gray) const;
    /// The pose of one detected marker of side `size` m; false when solvePnP fails.
    bool estimate_pose(MarkerObservation& marker, double size) const;

    const Camera& camera() const { return camera_; }
    const MarkerSizes& sizes() const { return sizes_; }

private:
    struct Impl;
    Camera camera_;
    MarkerSizes sizes_;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm::aruco
