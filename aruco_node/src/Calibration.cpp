#include <cpm/aruco/Calibration.hpp>

#include "ArucoCompat.hpp"

#include <cpm/Error.hpp>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <cstdio>

namespace cpm::aruco {
namespace {

compat::CharucoSpec spec_of(const CharucoBoard& b)
{
    return {b.squares_x, b.squares_y, b.square, b.marker, b.dictionary};
}

}  // namespace

CharucoBoard CharucoBoard::parse(const std::string& text)
{
    const std::string what = "board '" + text + "'";
    if (text.rfind("charuco:", 0) != 0) throw Error(what + ": expected charuco:XxY,SQUARE,MARKER (e.g. charuco:5x7,0.04,0.03)");
    CharucoBoard b;
    char dict[64] = "";
    int n = std::sscanf(text.c_str() + 8, "%dx%d,%lf,%lf,%63s", &b.squares_x, &b.squares_y, &b.square, &b.marker, dict);
    if (n < 4) throw Error(what + ": expected charuco:XxY,SQUARE,MARKER (e.g. charuco:5x7,0.04,0.03)");
    if (n == 5) b.dictionary = dict;
    if (b.squares_x < 3 || b.squares_y < 3 || b.squares_x > 50 || b.squares_y > 50) throw Error(what + ": 3..50 squares each way");
    if (b.squares_y % 2 == 0) {
        throw Error(what + ": use an odd number of rows (OpenCV 4.6 lays out boards with an even row count differently "
                           "from other versions, so such a board's corners would be misidentified)");
    }
    if (!(b.square > 0) || !(b.marker > 0) || b.marker >= b.square) throw Error(what + ": need 0 < MARKER < SQUARE (metres)");
    compat::dictionary(b.dictionary);  // names an unknown dictionary
    return b;
}

cv::Mat CharucoBoard::draw(int px_per_square) const
{
    const cv::Size size((squares_x + 2) * px_per_square, (squares_y + 2) * px_per_square);
    return compat::draw_charuco(spec_of(*this), size, px_per_square);
}

CalibrationResult calibrate(const std::vector<std::string>& images, const CharucoBoard& board)
{
    CalibrationResult result;
    std::vector<std::vector<int>> all_ids;
    std::vector<std::vector<cv::Point2f>> all_corners;
    cv::Size size;
    for (const auto& path : images) {
        cv::Mat gray = cv::imread(path, cv::IMREAD_GRAYSCALE);
        if (gray.empty()) throw Error(path + ": cannot read the image");
        if (size.empty()) size = gray.size();
        if (gray.size() != size) {
            throw Error(path + ": " + std::to_string(gray.cols) + "×" + std::to_string(gray.rows) + " px, but the first image is " +
                        std::to_string(size.width) + "×" + std::to_string(size.height));
        }
        std::vector<int> ids;
        std::vector<cv::Point2f> corners;
        compat::find_charuco(gray, spec_of(board), ids, corners);
        if (ids.size() < 6) {
            result.skipped.push_back(path + ": " + std::to_string(ids.size()) + " board corners found (need 6)");
            continue;
        }
        all_ids.push_back(std::move(ids));
        all_corners.push_back(std::move(corners));
    }
    if (all_ids.size() < 3) {
        throw Error("only " + std::to_string(all_ids.size()) + " of " + std::to_string(images.size()) +
                    " images show the board well enough (need 3, from different angles)");
    }
    cv::Mat k, dist;
    result.rms_error = compat::calibrate_charuco(all_ids, all_corners, spec_of(board), size, k, dist, 0);
    result.images_used = int(all_ids.size());
    result.camera.width = size.width;
    result.camera.height = size.height;
    result.camera.camera_matrix = cv::Matx33d(k.ptr<double>());
    for (int i = 0; i < 5 && i < int(dist.total()); ++i) result.camera.distortion[i] = dist.at<double>(i);
    result.camera.mount = {0, 0, 0, 0, 0};
    return result;
}

cv::Mat render_board_view(const CharucoBoard& board, const Camera& camera, const cv::Vec3d& rvec, const cv::Vec3d& tvec)
{
    const int ppsq = 80;
    cv::Mat tex = board.draw(ppsq);
    // Texture pixel (u, v) sits at board coordinates ((u + 0.5) / ppsq - 1, (v + 0.5) / ppsq - 1) squares
    // (the margin is one square); the board's chessboard corner grid starts at (1, 1) squares.
    const double m_per_px = board.square / ppsq;
    std::vector<cv::Point3d> plane;
    std::vector<cv::Point2f> src;
    for (auto [u, v] : {std::pair{0.0, 0.0}, {double(tex.cols), 0.0}, {double(tex.cols), double(tex.rows)}, {0.0, double(tex.rows)}}) {
        src.emplace_back(float(u - 0.5), float(v - 0.5));
        plane.emplace_back(u * m_per_px - board.square, v * m_per_px - board.square, 0);
    }
    std::vector<cv::Point2d> image;
    cv::projectPoints(plane, rvec, tvec, camera.camera_matrix, cv::noArray(), image);
    std::vector<cv::Point2f> dst(image.begin(), image.end());
    cv::Mat hom = cv::getPerspectiveTransform(src, dst);
    cv::Mat out(camera.height, camera.width, CV_8UC1, cv::Scalar(110));
    cv::warpPerspective(tex, out, hom, out.size(), cv::INTER_AREA, cv::BORDER_TRANSPARENT);
    return out;
}

}  // namespace cpm::aruco
