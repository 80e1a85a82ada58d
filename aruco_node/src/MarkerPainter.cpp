#include "MarkerPainter.hpp"

#include <cpm/Error.hpp>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <vector>

namespace cpm::aruco {

QuadSize quad_size(const std::array<cv::Point2d, 4>& corners)
{
    QuadSize q{0, 1e9};
    for (size_t i = 0; i < 4; ++i) {
        const double edge = cv::norm(corners[i] - corners[(i + 1) % 4]);
        q.side += edge / 4;
        q.shortest = std::min(q.shortest, edge);
    }
    return q;
}

bool whole_in_view(const std::array<cv::Point2d, 4>& corners, int width, int height)
{
    return std::all_of(corners.begin(), corners.end(),
                       [&](const cv::Point2d& p) { return p.x >= 3 && p.y >= 3 && p.x <= width - 4 && p.y <= height - 4; });
}

MarkerPainter::MarkerPainter(const RenderOptions& options)
    : options_(options), dictionary_(compat::dictionary(options.dictionary)), cells_(compat::marker_bits(*dictionary_) + 2),
      rng_(options.seed)
{
}

void MarkerPainter::check_id(int id, const std::string& what) const
{
    // drawMarker asserts on ids outside the dictionary; say which marker instead.
    const int size = compat::dictionary_size(*dictionary_);
    if (id < 0 || id >= size) {
        throw Error(what + ": marker id " + std::to_string(id) + " is not in " + options_.dictionary + " (ids 0.." +
                    std::to_string(size - 1) + ")");
    }
}

const cv::Mat& MarkerPainter::texture(int id, int px_per_cell)
{
    auto key = std::make_pair(id, px_per_cell);
    auto it = textures_.find(key);
    if (it != textures_.end()) return it->second;
    if (textures_.size() > 512) textures_.clear();  // bounded: many ids × many scales
    cv::Mat marker = compat::draw_marker(*dictionary_, id, cells_ * px_per_cell);
    cv::Mat padded;
    cv::copyMakeBorder(marker, padded, px_per_cell, px_per_cell, px_per_cell, px_per_cell, cv::BORDER_CONSTANT, 255);
    return textures_.emplace(key, padded).first->second;
}

bool MarkerPainter::paint(cv::Mat& frame, int id, const std::array<cv::Point2d, 4>& black, const std::array<cv::Point2d, 4>& outer)
{
    const QuadSize size = quad_size(black);
    if (size.side < 4) return false;
    // A texture no finer than the marker's most foreshortened edge: warping then only
    // magnifies, and a bilinear edge crosses mid-grey where the true edge is (minifying
    // would alias and move edges by a good part of a pixel).
    const int ppc = std::clamp(int(std::floor(size.shortest / cells_)), 1, 64);
    const cv::Mat& tex = texture(id, ppc);
    const double a = ppc - 0.5, b = ppc + cells_ * ppc - 0.5;  // the black square's edges in the texture
    const cv::Point2f src[4] = {{float(a), float(a)}, {float(b), float(a)}, {float(b), float(b)}, {float(a), float(b)}};
    const cv::Point2f dst[4] = {black[0], black[1], black[2], black[3]};
    const cv::Matx33d hom = cv::getPerspectiveTransform(src, dst);
    cv::Rect box = cv::boundingRect(std::vector<cv::Point2f>{outer[0], outer[1], outer[2], outer[3]});
    box.x -= 1;
    box.y -= 1;
    box.width += 3;
    box.height += 3;
    box &= cv::Rect(0, 0, frame.cols, frame.rows);
    if (box.empty()) return false;
    const cv::Matx33d shift(1, 0, -box.x, 0, 1, -box.y, 0, 0, 1);
    cv::Mat roi = frame(box);
    cv::warpPerspective(tex, roi, shift * hom, roi.size(), cv::INTER_LINEAR, cv::BORDER_TRANSPARENT);
    return true;
}

void MarkerPainter::sensor(cv::Mat& frame)
{
    if (options_.blur > 1) cv::blur(frame, frame, cv::Size(options_.blur, options_.blur));
    if (options_.noise_sigma > 0) {
        cv::Mat noise(frame.rows, frame.cols, CV_16S);
        rng_.fill(noise, cv::RNG::NORMAL, 0, options_.noise_sigma);
        cv::Mat sum;
        frame.convertTo(sum, CV_16S);
        sum += noise;
        sum.convertTo(frame, CV_8U);
    }
}

}  // namespace cpm::aruco
