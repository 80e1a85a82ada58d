#pragma once
// Sub-pixel marker corners from the marker's four edges: each edge located across its length
// (where the grey level crosses halfway between the black border and the white margin), a
// line fitted through it, and each corner where two lines meet. Unbiased where cornerSubPix
// pulls the corners of small markers inwards (by about 0.2 px at 25 px, 1.5 % of the distance).
#include <opencv2/core.hpp>

#include <vector>

namespace cpm::aruco {

/// Refines `quad` (clockwise, from detectMarkers) in place; `cells` is the marker's side in
/// cells (bits + 2). False (quad unchanged) when an edge cannot be located.
bool refine_corners_by_edges(const cv::Mat& gray, std::vector<cv::Point2f>& quad, int cells);

}  // namespace cpm::aruco
