#pragma once
// The one place that calls OpenCV's aruco module. OpenCV 4.6 (Debian 12) has the free
// functions of opencv_contrib's aruco; 4.7 moved them into objdetect as ArucoDetector,
// generateImageMarker and CharucoDetector. Porting cpm to a newer OpenCV changes this file only.
#include <opencv2/core.hpp>

#include <array>
#include <memory>
#include <string>
#include <vector>

namespace cpm::aruco::compat {

/// A predefined dictionary by its OpenCV name ("DICT_4X4_50", "DICT_APRILTAG_36h11", …).
/// Throws cpm::Error naming the name and listing the known ones.
struct Dictionary;
std::shared_ptr<const Dictionary> dictionary(const std::string& name);
/// Bits per side of the dictionary's markers (4 for DICT_4X4_*).
int marker_bits(const Dictionary& dictionary);
/// How many markers it has (ids 0 .. size-1).
int dictionary_size(const Dictionary& dictionary);

/// The detector parameters cpm exposes (the others: see parameters() in the .cpp).
struct DetectorSettings
{
    bool subpixel = true;         ///< sub-pixel corners: lines fitted to the edges (cornerSubPix where that fails)
    int subpixel_window = 5;      ///< px, cornerSubPix's largest window (half side, its winSize)
    bool aruco3 = false;          ///< useAruco3Detection (multi-scale)
};

/// Detector state: the dictionary and OpenCV's parameter object, made once.
class Detector
{
public:
    Detector(std::shared_ptr<const Dictionary> dictionary, const DetectorSettings& settings);
    ~Detector();
    Detector(Detector&&) noexcept;
    Detector& operator=(Detector&&) noexcept;
    /// Corners clockwise from the marker's top-left, as OpenCV gives them.
    void detect(const cv::Mat& gray, std::vector<int>& ids, std::vector<std::array<cv::Point2f, 4>>& corners) const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

/// The marker's image: black border and bits, `side` px, no white margin.
cv::Mat draw_marker(const Dictionary& dictionary, int id, int side);

/// ChArUco board (squares_x × squares_y squares; lengths in metres).
struct CharucoSpec
{
    int squares_x = 5, squares_y = 7;
    double square_length = 0.04, marker_length = 0.03;
    std::string dictionary = "DICT_4X4_50";
};
/// The board as an image of `size` px with `margin` px of white around it.
cv::Mat draw_charuco(const CharucoSpec& spec, cv::Size size, int margin);
/// The chessboard corners found in one image (ids and sub-pixel positions); empty when fewer
/// than `min_markers` markers are seen.
void find_charuco(const cv::Mat& gray, const CharucoSpec& spec, std::vector<int>& ids, std::vector<cv::Point2f>& corners);
/// calibrateCameraCharuco; returns the RMS reprojection error in px.
double calibrate_charuco(const std::vector<std::vector<int>>& ids, const std::vector<std::vector<cv::Point2f>>& corners,
                         const CharucoSpec& spec, cv::Size image_size, cv::Mat& camera_matrix, cv::Mat& distortion, int flags);

}  // namespace cpm::aruco::compat
