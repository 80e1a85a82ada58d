#include "CornerRefine.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>

namespace cpm::aruco {
namespace {

/// Bilinear grey level at (x, y); false outside the image.
bool sample(const cv::Mat& gray, double x, double y, double& value)
{
    if (x < 0 || y < 0 || x > gray.cols - 1.001 || y > gray.rows - 1.001) return false;
    const int x0 = int(x), y0 = int(y);
    const double fx = x - x0, fy = y - y0;
    const uint8_t* r0 = gray.ptr<uint8_t>(y0) + x0;
    const uint8_t* r1 = gray.ptr<uint8_t>(y0 + 1) + x0;
    value = (1 - fy) * ((1 - fx) * r0[0] + fx * r0[1]) + fy * ((1 - fx) * r1[0] + fx * r1[1]);
    return true;
}

/// A line through `point` along `direction` (unit).
struct Line
{
    cv::Point2d point, direction;
};

bool intersect(const Line& a, const Line& b, cv::Point2d& out)
{
    const double denom = a.direction.x * b.direction.y - a.direction.y * b.direction.x;
    if (std::abs(denom) < 1e-3) return false;
    const cv::Point2d w = b.point - a.point;
    const double t = (w.x * b.direction.y - w.y * b.direction.x) / denom;
    out = a.point + t * a.direction;
    return true;
}

/// The edge from p to q, located across its middle part: a line through the points where the
/// profile across it crosses halfway between the dark inside and the light outside.
bool fit_edge(const cv::Mat& gray, cv::Point2d p, cv::Point2d q, cv::Point2d centre, double reach, Line& line)
{
    const cv::Point2d along = q - p;
    const double length = std::hypot(along.x, along.y);
    if (length < 4) return false;
    const cv::Point2d u = along / length;
    cv::Point2d n(u.y, -u.x);
    if ((p - centre).dot(n) < 0) n = -n;  // outwards
    std::vector<cv::Point2d> points;
    const int steps = std::max(5, int(length * 0.7));
    constexpr double kStep = 0.25;
    const int half = int(std::ceil(reach / kStep));
    std::vector<double> profile(size_t(2 * half + 1));
    for (int i = 0; i < steps; ++i) {
        const cv::Point2d at = p + (0.15 + 0.7 * i / (steps - 1)) * along;
        bool inside_image = true;
        for (int k = -half; k <= half && inside_image; ++k) {
            const cv::Point2d s = at + (k * kStep) * n;
            inside_image = sample(gray, s.x, s.y, profile[size_t(k + half)]);
        }
        if (!inside_image) continue;
        const auto [lo, hi] = std::minmax_element(profile.begin(), profile.end());
        if (*hi - *lo < 20) continue;  // no edge here
        const double mid = (*lo + *hi) / 2;
        // The crossing nearest to the initial edge, from dark (inside) to light (outside).
        double best = 1e9;
        for (int k = 0; k + 1 < int(profile.size()); ++k) {
            if (profile[size_t(k)] < mid && profile[size_t(k + 1)] >= mid) {
                const double f = (mid - profile[size_t(k)]) / (profile[size_t(k + 1)] - profile[size_t(k)]);
                const double offset = (k - half + f) * kStep;
                if (std::abs(offset) < std::abs(best)) best = offset;
            }
        }
        if (best < 1e8) points.push_back(at + best * n);
    }
    if (points.size() < 4) return false;
    cv::Vec4f fitted;
    std::vector<cv::Point2f> pts(points.begin(), points.end());
    cv::fitLine(pts, fitted, cv::DIST_L2, 0, 0.01, 0.01);
    line.direction = {fitted[0], fitted[1]};
    line.point = {fitted[2], fitted[3]};
    return true;
}

}  // namespace

bool refine_corners_by_edges(const cv::Mat& gray, std::vector<cv::Point2f>& quad, int cells)
{
    if (quad.size() != 4 || gray.type() != CV_8UC1) return false;
    std::array<cv::Point2d, 4> corners;
    for (int k = 0; k < 4; ++k) corners[size_t(k)] = quad[size_t(k)];
    for (int pass = 0; pass < 2; ++pass) {
        cv::Point2d centre(0, 0);
        double shortest = 1e9;
        for (int k = 0; k < 4; ++k) {
            centre += corners[size_t(k)] * 0.25;
            shortest = std::min(shortest, cv::norm(corners[size_t(k)] - corners[size_t((k + 1) % 4)]));
        }
        // Across the edge no further than most of a cell: the black border inside, the white
        // margin outside, not the bits beyond.
        const double reach = std::clamp(0.7 * shortest / cells, 1.0, 4.0);
        std::array<Line, 4> lines;
        for (int k = 0; k < 4; ++k) {
            if (!fit_edge(gray, corners[size_t(k)], corners[size_t((k + 1) % 4)], centre, reach, lines[size_t(k)])) return pass > 0;
        }
        std::array<cv::Point2d, 4> refined;
        for (int k = 0; k < 4; ++k) {
            // Corner k is where the edge before it (k-1 → k) meets the edge after it (k → k+1).
            if (!intersect(lines[size_t((k + 3) % 4)], lines[size_t(k)], refined[size_t(k)])) return pass > 0;
            if (cv::norm(refined[size_t(k)] - corners[size_t(k)]) > 3) return pass > 0;  // not the same corner
        }
        corners = refined;
        for (int k = 0; k < 4; ++k) quad[size_t(k)] = cv::Point2f(corners[size_t(k)]);
    }
    return true;
}

}  // namespace cpm::aruco
