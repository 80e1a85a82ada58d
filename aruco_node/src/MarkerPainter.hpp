#pragma once
// What both synthetic cameras (the car's, the overhead one) share: a marker's texture, warped
// onto the frame through the projections of its corners, and the sensor's noise and blur.
#include "ArucoCompat.hpp"

#include <cpm/aruco/Renderer.hpp>

#include <opencv2/core.hpp>

#include <array>
#include <map>
#include <memory>
#include <string>
#include <utility>

namespace cpm::aruco {

/// A projected quad's mean side and its shortest side, px.
struct QuadSize
{
    double side = 0, shortest = 0;
};
QuadSize quad_size(const std::array<cv::Point2d, 4>& corners);
/// All four corners at least 3 px inside a width × height image.
bool whole_in_view(const std::array<cv::Point2d, 4>& corners, int width, int height);

class MarkerPainter
{
public:
    /// Throws cpm::Error naming an unknown dictionary.
    explicit MarkerPainter(const RenderOptions& options);

    /// Cells per side of a marker with its black border (6 for DICT_4X4_*).
    int cells() const { return cells_; }
    /// Throws cpm::Error naming a marker id the dictionary does not have (`what`: where it is).
    void check_id(int id, const std::string& what) const;
    /// How far out the white quiet zone's corners are, as a multiple of the black square's half side.
    double quiet_zone_scale() const { return double(cells_ + 2) / cells_; }

    /// Draws marker `id` into `frame`: `black` are the black square's corners in the detector's
    /// order (px), `outer` the quiet zone's. False when it is too small to draw (under 4 px).
    bool paint(cv::Mat& frame, int id, const std::array<cv::Point2d, 4>& black, const std::array<cv::Point2d, 4>& outer);

    /// The sensor: blur, then Gaussian noise (seeded).
    void sensor(cv::Mat& frame);

private:
    const cv::Mat& texture(int id, int px_per_cell);

    RenderOptions options_;
    std::shared_ptr<const compat::Dictionary> dictionary_;
    int cells_ = 6;
    std::map<std::pair<int, int>, cv::Mat> textures_;  // (id, px per cell) → marker with its quiet zone
    cv::RNG rng_;
};

}  // namespace cpm::aruco
