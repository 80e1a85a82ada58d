#include "ArucoCompat.hpp"
#include "CornerRefine.hpp"

#include <cpm/Error.hpp>

#include <opencv2/aruco.hpp>
#include <opencv2/aruco/charuco.hpp>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <utility>

namespace cpm::aruco::compat {

struct Dictionary
{
    cv::Ptr<cv::aruco::Dictionary> cv;
};

namespace {

#ifdef __SANITIZE_THREAD__
// Under ThreadSanitizer OpenCV runs sequentially: its parallel loops run on TBB's threads, and
// Debian's libtbb is not instrumented, so TSan cannot see TBB hand the work back and reports
// every buffer OpenCV allocated on a worker and freed on the caller. One thread shows the same
// results; the races TSan is here for are cpm's.
const bool kOpenCvSequential = (cv::setNumThreads(0), true);
#endif

const std::pair<const char*, cv::aruco::PREDEFINED_DICTIONARY_NAME> kDictionaries[] = {
    {"DICT_4X4_50", cv::aruco::DICT_4X4_50},         {"DICT_4X4_100", cv::aruco::DICT_4X4_100},
    {"DICT_4X4_250", cv::aruco::DICT_4X4_250},       {"DICT_4X4_1000", cv::aruco::DICT_4X4_1000},
    {"DICT_5X5_50", cv::aruco::DICT_5X5_50},         {"DICT_5X5_100", cv::aruco::DICT_5X5_100},
    {"DICT_5X5_250", cv::aruco::DICT_5X5_250},       {"DICT_5X5_1000", cv::aruco::DICT_5X5_1000},
    {"DICT_6X6_50", cv::aruco::DICT_6X6_50},         {"DICT_6X6_100", cv::aruco::DICT_6X6_100},
    {"DICT_6X6_250", cv::aruco::DICT_6X6_250},       {"DICT_6X6_1000", cv::aruco::DICT_6X6_1000},
    {"DICT_7X7_50", cv::aruco::DICT_7X7_50},         {"DICT_7X7_100", cv::aruco::DICT_7X7_100},
    {"DICT_7X7_250", cv::aruco::DICT_7X7_250},       {"DICT_7X7_1000", cv::aruco::DICT_7X7_1000},
    {"DICT_ARUCO_ORIGINAL", cv::aruco::DICT_ARUCO_ORIGINAL}, {"DICT_APRILTAG_16h5", cv::aruco::DICT_APRILTAG_16h5},
    {"DICT_APRILTAG_25h9", cv::aruco::DICT_APRILTAG_25h9},   {"DICT_APRILTAG_36h10", cv::aruco::DICT_APRILTAG_36h10},
    {"DICT_APRILTAG_36h11", cv::aruco::DICT_APRILTAG_36h11},
};

cv::Ptr<cv::aruco::DetectorParameters> parameters(const DetectorSettings& s)
{
    auto p = cv::aruco::DetectorParameters::create();
    // Sub-pixel refinement is cpm's own (Detector::detect): OpenCV 4.6's uses one window for
    // every marker, which misplaces the corners of small ones (fixed in 4.9).
    p->cornerRefinementMethod = cv::aruco::CORNER_REFINE_NONE;
    p->useAruco3Detection = s.aruco3;
    // Two threshold scales (5, 15 px) instead of OpenCV's three (3, 13, 23) and 6 px per cell
    // when reading the bits (OpenCV: 4): measured on noisy, blurred markers of 20-30 px,
    // 88 % → 97 % found (bench/aruco), no slower, still no false marker in 1000 cluttered
    // frames (8 px per cell found 99 % but one false marker). bench/aruco's plain reference
    // uses the same two values.
    p->adaptiveThreshWinSizeMin = 5;
    p->perspectiveRemovePixelPerCell = 6;
    return p;
}

cv::Ptr<cv::aruco::CharucoBoard> board(const CharucoSpec& spec)
{
    return cv::aruco::CharucoBoard::create(spec.squares_x, spec.squares_y, float(spec.square_length), float(spec.marker_length),
                                           dictionary(spec.dictionary)->cv);
}

}  // namespace

std::shared_ptr<const Dictionary> dictionary(const std::string& name)
{
    for (const auto& [known, id] : kDictionaries) {
        if (name == known) return std::make_shared<const Dictionary>(Dictionary{cv::aruco::getPredefinedDictionary(id)});
    }
    std::string list;
    for (const auto& [known, id] : kDictionaries) list += (list.empty() ? "" : ", ") + std::string(known);
    throw Error("unknown dictionary '" + name + "' (known: " + list + ")");
}

int marker_bits(const Dictionary& dictionary) { return dictionary.cv->markerSize; }

int dictionary_size(const Dictionary& dictionary) { return dictionary.cv->bytesList.rows; }

struct Detector::Impl
{
    std::shared_ptr<const Dictionary> dictionary;
    cv::Ptr<cv::aruco::DetectorParameters> parameters;
    bool subpixel;
    int max_window;
    // Reused between frames: detectMarkers fills them.
    mutable std::vector<std::vector<cv::Point2f>> corners;
};

Detector::Detector(std::shared_ptr<const Dictionary> dictionary, const DetectorSettings& settings)
    : impl_(std::make_unique<Impl>(Impl{std::move(dictionary), parameters(settings), settings.subpixel, settings.subpixel_window, {}}))
{
}
Detector::~Detector() = default;
Detector::Detector(Detector&&) noexcept = default;
Detector& Detector::operator=(Detector&&) noexcept = default;

void Detector::detect(const cv::Mat& gray, std::vector<int>& ids, std::vector<std::array<cv::Point2f, 4>>& corners) const
{
    cv::aruco::detectMarkers(gray, impl_->dictionary->cv, impl_->corners, ids, impl_->parameters);
    if (impl_->subpixel) {
        // Corners from lines fitted to the marker's edges; where an edge cannot be located,
        // cornerSubPix with a window of about 0.45 of a bit's side along the most foreshortened
        // edge (at most subpixel_window): a larger one reaches the inner bits' corners and pulls
        // the corner off by a pixel or more on small markers.
        const double cells = impl_->dictionary->cv->markerSize + 2;
        for (auto& quad : impl_->corners) {
            if (refine_corners_by_edges(gray, quad, int(cells))) continue;
            double shortest = 1e9;
            for (int k = 0; k < 4; ++k) shortest = std::min(shortest, double(cv::norm(quad[k] - quad[(k + 1) % 4])));
            const int window = std::clamp(int(std::lround(0.45 * shortest / cells)), 1, std::max(1, impl_->max_window));
            cv::cornerSubPix(gray, quad, cv::Size(window, window), cv::Size(-1, -1),
                             cv::TermCriteria(cv::TermCriteria::MAX_ITER | cv::TermCriteria::EPS, 30, 0.01));
        }
    }
    corners.resize(impl_->corners.size());
    for (size_t i = 0; i < corners.size(); ++i) {
        for (int k = 0; k < 4; ++k) corners[i][k] = impl_->corners[i][k];
    }
}

cv::Mat draw_marker(const Dictionary& dictionary, int id, int side)
{
    cv::Mat out;
    cv::aruco::drawMarker(dictionary.cv, id, side, out, 1);
    return out;
}

cv::Mat draw_charuco(const CharucoSpec& spec, cv::Size size, int margin)
{
    cv::Mat out;
    board(spec)->draw(size, out, margin, 1);
    return out;
}

void find_charuco(const cv::Mat& gray, const CharucoSpec& spec, std::vector<int>& ids, std::vector<cv::Point2f>& corners)
{
    auto b = board(spec);
    std::vector<int> marker_ids;
    std::vector<std::vector<cv::Point2f>> marker_corners;
    cv::aruco::detectMarkers(gray, b->dictionary, marker_corners, marker_ids, parameters({}));
    ids.clear();
    corners.clear();
    if (marker_ids.size() < 2) return;
    cv::aruco::interpolateCornersCharuco(marker_corners, marker_ids, gray, b, corners, ids);
}

double calibrate_charuco(const std::vector<std::vector<int>>& ids, const std::vector<std::vector<cv::Point2f>>& corners,
                         const CharucoSpec& spec, cv::Size image_size, cv::Mat& camera_matrix, cv::Mat& distortion, int flags)
{
    return cv::aruco::calibrateCameraCharuco(corners, ids, board(spec), image_size, camera_matrix, distortion, cv::noArray(),
                                             cv::noArray(), flags);
}

}  // namespace cpm::aruco::compat
