#pragma once
#include <cpm/aruco/Camera.hpp>

#include <opencv2/core.hpp>

#include <string>
#include <vector>

namespace cpm::aruco {

/// A ChArUco board: squares_x × squares_y chessboard squares of `square` m with markers of
/// `marker` m in the white ones.
struct CharucoBoard
{
    int squares_x = 5, squares_y = 7;
    double square = 0.04, marker = 0.03;
    std::string dictionary = "DICT_4X4_50";

    /// "charuco:5x7,0.04,0.03" (optionally ",DICT_…"). Throws cpm::Error naming what is wrong.
    static CharucoBoard parse(const std::string& spec);
    /// The board's image, `px_per_square` px a square, with a white margin of one square.
    cv::Mat draw(int px_per_square) const;
};

/// What a calibration found.
struct CalibrationResult
{
    Camera camera;            ///< intrinsics found; mount left at zero
    double rms_error = 0;     ///< reprojection error, px
    int images_used = 0;
    std::vector<std::string> skipped;  ///< "FILE: why" for each image that was not used
};

/// Calibrates from images of the board (OpenCV's calibrateCameraCharuco). Throws cpm::Error
/// naming an unreadable image, images of different sizes, or too few usable views.
CalibrationResult calibrate(const std::vector<std::string>& images, const CharucoBoard& board);

/// The board as `camera` sees it when the board's frame (origin at its top-left corner, x
/// along the squares, y down the board, z into it) sits at rvec/tvec in the camera frame:
/// white paper on a grey background, through the pinhole model (distortion not rendered).
/// For tests and examples.
cv::Mat render_board_view(const CharucoBoard& board, const Camera& camera, const cv::Vec3d& rvec, const cv::Vec3d& tvec);

}  // namespace cpm::aruco
