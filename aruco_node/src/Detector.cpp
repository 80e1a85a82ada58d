#include <cpm/aruco/Detector.hpp>

#include "ArucoCompat.hpp"

#include <cpm/vehicle/World.hpp>

#include <opencv2/calib3d.hpp>

#include <cmath>

namespace cpm::aruco {

MarkerSizes MarkerSizes::from_world(const vehicle::World& world, double fallback)
{
    MarkerSizes s;
    s.fallback = fallback;
    for (const auto& m : world.markers()) s.by_id[m.id] = m.size;
    return s;
}

double MarkerSizes::of(int id) const
{
    auto it = by_id.find(id);
    return it == by_id.end() ? fallback : it->second;
}

struct MarkerDetector::Impl
{
    compat::Detector detector;
    mutable std::vector<int> ids;
    mutable std::vector<std::array<cv::Point2f, 4>> corners;
};

MarkerDetector::MarkerDetector(Camera camera, DetectorOptions options, MarkerSizes sizes)
    : camera_(std::move(camera)), sizes_(std::move(sizes)),
      impl_(std::make_unique<Impl>(Impl{compat::Detector(compat::dictionary(options.dictionary),
                                                         {.subpixel = options.subpixel,
                                                          .subpixel_window = options.subpixel_window,
                                                          .aruco3 = options.aruco3}),
                                        {},
                                        {}}))
{
}

MarkerDetector::~MarkerDetector() = default;
MarkerDetector::MarkerDetector(MarkerDetector&&) noexcept = default;
MarkerDetector& MarkerDetector::operator=(MarkerDetector&&) noexcept = default;

void MarkerDetector::detect(const cv::Mat& gray, std::vector<MarkerObservation>& out) const
{
    impl_->detector.detect(gray, impl_->ids, impl_->corners);
    out.resize(impl_->ids.size());
    for (size_t i = 0; i < out.size(); ++i) out[i] = MarkerObservation{.id = impl_->ids[i], .corners = impl_->corners[i]};
}

std::vector<MarkerObservation> MarkerDetector::observe(const cv::Mat& gray) const
{
    std::vector<MarkerObservation> out;
    detect(gray, out);
    for (auto& m : out) {
        const double size = sizes_.of(m.id);
        if (size > 0) estimate_pose(m, size);
    }
    return out;
}

bool MarkerDetector::estimate_pose(MarkerObservation& m, double size) const
{
    // IPPE_SQUARE's object points: the marker's corners in its own frame (x right, y up, z out
    // of its face), in the detector's corner order.
    const float h = float(size / 2);
    const cv::Point3f object[4] = {{-h, h, 0}, {h, h, 0}, {h, -h, 0}, {-h, -h, 0}};
    // Both of IPPE's solutions, best reprojection first; a solution whose face looks away from
    // the camera cannot be (the back of a marker is blank), whatever its error. OpenCV 4.6's
    // IPPE now and then returns two wrong solutions (tens of px off) for a good quad: then the
    // iterative solver (Levenberg-Marquardt) takes over, and its answer must reproject well.
    const cv::Mat object_points(4, 1, CV_32FC3, const_cast<cv::Point3f*>(object));
    const cv::Mat image_points(4, 1, CV_32FC2, m.corners.data());
    constexpr double kMaxReprojectionPx = 1.0;
    std::vector<cv::Mat> rvecs, tvecs;
    std::vector<double> errors;
    cv::Matx33d r;
    cv::Vec3d tvec;
    // Takes a solution if it is finite, in front of the camera and facing it.
    auto take = [&](const cv::Mat& rvec, const cv::Mat& tv_mat) {
        cv::Mat rm, tm;  // float input may give float solutions
        rvec.convertTo(rm, CV_64F);
        tv_mat.convertTo(tm, CV_64F);
        const cv::Vec3d rv(rm.ptr<double>()), tv(tm.ptr<double>());
        if (!std::isfinite(rv[0] + rv[1] + rv[2]) || !std::isfinite(tv[0] + tv[1] + tv[2]) || tv[2] <= 0) return false;
        cv::Matx33d ri;
        cv::Rodrigues(rv, ri);
        if (cv::Vec3d(ri(0, 2), ri(1, 2), ri(2, 2)).dot(-tv) <= 0) return false;
        r = ri;
        tvec = tv;
        return true;
    };
    bool found = false;
    try {
        cv::solvePnPGeneric(object_points, image_points, camera_.camera_matrix, camera_.distortion, rvecs, tvecs, false,
                            cv::SOLVEPNP_IPPE_SQUARE, cv::noArray(), cv::noArray(), errors);
        for (size_t i = 0; i < rvecs.size() && !found; ++i) {
            if (errors[i] <= kMaxReprojectionPx) found = take(rvecs[i], tvecs[i]);
        }
        if (!found) {
            rvecs.clear();
            tvecs.clear();
            errors.clear();
            cv::solvePnPGeneric(object_points, image_points, camera_.camera_matrix, camera_.distortion, rvecs, tvecs, false,
                                cv::SOLVEPNP_ITERATIVE, cv::noArray(), cv::noArray(), errors);
            if (!rvecs.empty() && errors[0] <= kMaxReprojectionPx) found = take(rvecs[0], tvecs[0]);
        }
    } catch (const cv::Exception&) {
        return false;
    }
    if (!found) return false;
    const cv::Vec3d centre = camera_.to_car(tvec);
    const cv::Vec3d normal = camera_.car_from_camera_rotation() * cv::Vec3d(r(0, 2), r(1, 2), r(2, 2));
    m.has_pose = true;
    m.x = centre[0];
    m.y = centre[1];
    m.z = centre[2];
    m.yaw = std::atan2(normal[1], normal[0]);
    m.distance = cv::norm(tvec);
    return true;
}

}  // namespace cpm::aruco
