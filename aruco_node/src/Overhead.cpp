#include <cpm/aruco/Overhead.hpp>

#include "MarkerPainter.hpp"

#include <cpm/Error.hpp>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

namespace cpm::aruco {
namespace {

/// The camera's pose as OpenCV's projection takes it: map → camera (rvec, tvec).
struct Extrinsics
{
    cv::Vec3d rvec, tvec;
};

Extrinsics extrinsics(const OverheadPose& pose)
{
    const cv::Matx33d map_to_camera = pose.rotation.t();
    Extrinsics e;
    cv::Rodrigues(map_to_camera, e.rvec);
    e.tvec = -(map_to_camera * pose.position);
    return e;
}

const OverheadPose& overhead_pose_of(const Camera& camera, const char* who)
{
    if (!camera.overhead) {
        throw Error(std::string(who) + ": the camera file has no overhead pose (world_x, world_y, world_z, world_rotation); "
                                       "locate the camera first: cpm camera locate --camera FILE --world FILE --image IMAGE");
    }
    return *camera.overhead;
}

bool has_distortion(const Camera& camera)
{
    for (int i = 0; i < 5; ++i) {
        if (camera.distortion[i] != 0) return true;
    }
    return false;
}

std::vector<cv::Point2d> project_points(const std::vector<cv::Point3d>& points, const Extrinsics& e, const cv::Matx33d& k,
                                        const cv::Vec<double, 5>& distortion)
{
    std::vector<cv::Point2d> image;
    cv::projectPoints(points, e.rvec, e.tvec, k, distortion, image);
    return image;
}

}  // namespace

std::array<cv::Vec3d, 4> flat_marker_corners(double x, double y, double z, double yaw, double size)
{
    // The marker lies face up: its x axis along yaw, its y axis (to the printed top) 90° left of
    // it, z up. The detector's order: top-left, top-right, bottom-right, bottom-left.
    const double h = size / 2;
    const cv::Vec3d c(x, y, z), u(std::cos(yaw), std::sin(yaw), 0), v(-std::sin(yaw), std::cos(yaw), 0);
    return {c - h * u + h * v, c + h * u + h * v, c + h * u - h * v, c - h * u - h * v};
}

double rotation_angle(const cv::Matx33d& a, const cv::Matx33d& b)
{
    const cv::Matx33d d = a.t() * b;
    return std::acos(std::clamp((cv::trace(d) - 1) / 2, -1.0, 1.0));
}

// ---------------------------------------------------------------------------------------------
// The synthetic overhead camera

struct OverheadRenderer::Impl
{
    Impl(const Camera& c, const RenderOptions& o, const vehicle::VehicleParameters& b)
        : camera(c), painter(o), options(o), body(b), pose(extrinsics(overhead_pose_of(camera, "the overhead camera")))
    {
        canvas_k = camera.camera_matrix;
        if (has_distortion(camera)) make_canvas();
    }

    /// Where each pixel of the distorted frame looks, on an ideal pinhole canvas large enough
    /// to hold all of them: the frame is then the canvas remapped.
    void make_canvas()
    {
        std::vector<cv::Point2f> pixels, ideal;
        pixels.reserve(size_t(camera.width) * camera.height);
        for (int v = 0; v < camera.height; ++v) {
            for (int u = 0; u < camera.width; ++u) pixels.emplace_back(float(u), float(v));
        }
        cv::undistortPoints(pixels, ideal, camera.camera_matrix, camera.distortion, cv::noArray(), camera.camera_matrix);
        float min_x = 0, min_y = 0, max_x = float(camera.width), max_y = float(camera.height);
        for (const auto& p : ideal) {
            min_x = std::min(min_x, p.x);
            min_y = std::min(min_y, p.y);
            max_x = std::max(max_x, p.x);
            max_y = std::max(max_y, p.y);
        }
        const float ox = std::ceil(-min_x) + 2, oy = std::ceil(-min_y) + 2;
        canvas_k(0, 2) += ox;
        canvas_k(1, 2) += oy;
        canvas.create(int(std::ceil(max_y + oy)) + 3, int(std::ceil(max_x + ox)) + 3, CV_8UC1);
        cv::Mat map_x(camera.height, camera.width, CV_32F), map_y(camera.height, camera.width, CV_32F);
        for (int v = 0, i = 0; v < camera.height; ++v) {
            for (int u = 0; u < camera.width; ++u, ++i) {
                map_x.at<float>(v, u) = ideal[size_t(i)].x + ox;
                map_y.at<float>(v, u) = ideal[size_t(i)].y + oy;
            }
        }
        cv::convertMaps(map_x, map_y, map1, map2, CV_16SC2);
        distorted = true;
    }

    std::vector<cv::Point2d> on_canvas(const std::vector<cv::Point3d>& points) const
    {
        return project_points(points, pose, canvas_k, cv::Vec<double, 5>(0, 0, 0, 0, 0));
    }
    std::vector<cv::Point2d> in_frame(const std::vector<cv::Point3d>& points) const
    {
        return project_points(points, pose, camera.camera_matrix, camera.distortion);
    }

    /// With distortion: the frame region a shape covers once the lens has bent its straight
    /// edges (5 points along each side of its outline), to be remapped from the canvas.
    void mark_dirty(const std::array<cv::Vec3d, 4>& outline)
    {
        if (!distorted) return;
        std::vector<cv::Point3d> points;
        for (size_t i = 0; i < 4; ++i) {
            for (int k = 0; k < 5; ++k) points.emplace_back(outline[i] + (outline[(i + 1) % 4] - outline[i]) * (k / 5.0));
        }
        const auto image = in_frame(points);
        cv::Rect box = cv::boundingRect(std::vector<cv::Point2f>(image.begin(), image.end()));
        box.x -= 3;
        box.y -= 3;
        box.width += 7;
        box.height += 7;
        box &= cv::Rect(0, 0, camera.width, camera.height);
        if (!box.empty()) dirty.push_back(box);
    }

    /// A flat marker at (x, y, z) painted on the target; its truth in the frame (if asked).
    void flat_marker(cv::Mat& target, std::vector<OverheadTruth>* truth, int id, int vehicle_id, double x, double y, double z, double yaw,
                     double size)
    {
        const auto black = flat_marker_corners(x, y, z, yaw, size);
        const auto outer = flat_marker_corners(x, y, z, yaw, size * painter.quiet_zone_scale());
        std::vector<cv::Point3d> object(black.begin(), black.end());
        object.insert(object.end(), outer.begin(), outer.end());
        const auto ideal = on_canvas(object);
        if (!painter.paint(target, id, {ideal[0], ideal[1], ideal[2], ideal[3]}, {ideal[4], ideal[5], ideal[6], ideal[7]})) return;
        mark_dirty(outer);
        if (!truth) return;
        const auto seen = in_frame({object.begin(), object.begin() + 4});
        const std::array<cv::Point2d, 4> corners{seen[0], seen[1], seen[2], seen[3]};
        OverheadTruth t{.id = id, .vehicle_id = vehicle_id};
        for (size_t i = 0; i < 4; ++i) t.corners[i] = corners[i];
        t.side_px = quad_size(corners).side;
        t.whole_in_view = whole_in_view(corners, camera.width, camera.height);
        truth->push_back(t);
    }

    /// A car: a dark box from the rear overhang to the front, its top at the roof's height, and
    /// its roof marker (if it wears one).
    void draw_car(cv::Mat& target, std::vector<OverheadTruth>* truth, const OverheadCar& car, const vehicle::RoofMarker* roof)
    {
        const double z = roof ? roof->z : 0.1;
        const double c = std::cos(car.pose.yaw), s = std::sin(car.pose.yaw);
        const double back = -body.rear_overhang, front = body.length - body.rear_overhang, half = body.width / 2;
        std::array<cv::Vec3d, 4> outline;
        const double xs[4] = {back, front, front, back}, ys[4] = {half, half, -half, -half};
        for (size_t i = 0; i < 4; ++i) outline[i] = {car.pose.x + c * xs[i] - s * ys[i], car.pose.y + s * xs[i] + c * ys[i], z};
        std::vector<cv::Point> poly;
        for (const auto& p : on_canvas({outline.begin(), outline.end()})) poly.emplace_back(int(std::lround(p.x * 16)), int(std::lround(p.y * 16)));
        cv::fillConvexPoly(target, poly, cv::Scalar(40), cv::LINE_AA, 4);
        mark_dirty(outline);
        if (roof) flat_marker(target, truth, roof->id, car.vehicle_id, car.pose.x, car.pose.y, z, car.pose.yaw, roof->size);
    }

    const Camera& camera;
    MarkerPainter painter;
    RenderOptions options;
    vehicle::VehicleParameters body;
    Extrinsics pose;
    cv::Matx33d canvas_k;
    bool distorted = false;
    cv::Mat canvas, map1, map2;          ///< with distortion: the pinhole canvas and its remap
    std::vector<cv::Rect> dirty;         ///< frame regions drawn this frame (remapped from the canvas)
};

OverheadRenderer::OverheadRenderer(vehicle::World world, Camera camera, RenderOptions options, vehicle::VehicleParameters body)
    : world_(std::move(world)), camera_(std::move(camera)), impl_(std::make_unique<Impl>(camera_, options, body))
{
    for (const auto& r : world_.roof_markers()) impl_->painter.check_id(r.id, "the roof marker of car " + std::to_string(r.vehicle_id));
    for (const auto& f : world_.floor_markers()) impl_->painter.check_id(f.id, "a floor marker");
}

OverheadRenderer::~OverheadRenderer() = default;

cv::Point2d OverheadRenderer::project(const cv::Vec3d& p) const { return impl_->in_frame({cv::Point3d(p)})[0]; }

void OverheadRenderer::render(const std::vector<OverheadCar>& cars, cv::Mat& frame, std::vector<OverheadTruth>* truth)
{
    Impl& d = *impl_;
    frame.create(camera_.height, camera_.width, CV_8UC1);
    frame.setTo(d.options.floor_grey);
    cv::Mat& target = d.distorted ? d.canvas : frame;
    if (d.distorted) target.setTo(d.options.floor_grey);
    d.dirty.clear();
    if (truth) truth->clear();
    for (const auto& f : world_.floor_markers()) d.flat_marker(target, truth, f.id, 0, f.x, f.y, 0, f.yaw, f.size);
    for (const auto& car : cars) d.draw_car(target, truth, car, world_.roof_marker_of(car.vehicle_id));
    for (const auto& box : d.dirty) {
        cv::Mat out = frame(box);
        cv::remap(d.canvas, out, d.map1(box), d.map2(box), cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(d.options.floor_grey));
    }
    d.painter.sensor(frame);
}

// ---------------------------------------------------------------------------------------------
// Locating the cars

struct OverheadLocator::Impl
{
    MarkerDetector detector;
    OverheadPose pose;
    Extrinsics extrinsics;
    mutable std::vector<MarkerObservation> seen;
    std::map<int, const vehicle::FloorMarker*> floor;
};

OverheadLocator::OverheadLocator(vehicle::World world, Camera camera, DetectorOptions options)
    : world_(std::move(world)), camera_(std::move(camera)),
      impl_(std::make_unique<Impl>(Impl{MarkerDetector(camera_, options), overhead_pose_of(camera_, "the IPS"), {}, {}, {}}))
{
    impl_->extrinsics = extrinsics(impl_->pose);
    for (const auto& f : world_.floor_markers()) impl_->floor[f.id] = &f;
    if (world_.roof_markers().empty()) throw Error("the IPS: the world has no roof_markers (which marker is on which car)");
}

OverheadLocator::~OverheadLocator() = default;
OverheadLocator::OverheadLocator(OverheadLocator&&) noexcept = default;
OverheadLocator& OverheadLocator::operator=(OverheadLocator&&) noexcept = default;

cv::Vec3d OverheadLocator::on_plane(const cv::Point2f& px, double z) const
{
    std::vector<cv::Point2f> in{px}, out;
    cv::undistortPoints(in, out, camera_.camera_matrix, camera_.distortion);
    const cv::Vec3d ray = impl_->pose.rotation * cv::Vec3d(out[0].x, out[0].y, 1);
    const cv::Vec3d& c = impl_->pose.position;
    if (std::abs(ray[2]) < 1e-12 || (z - c[2]) / ray[2] <= 0) {
        const double nan = std::numeric_limits<double>::quiet_NaN();
        return {nan, nan, nan};
    }
    return c + ray * ((z - c[2]) / ray[2]);
}

OverheadView OverheadLocator::locate(const cv::Mat& gray) const
{
    const Impl& d = *impl_;
    OverheadView view;
    d.detector.detect(gray, d.seen);
    std::map<int, int> count;
    for (const auto& m : d.seen) ++count[m.id];
    double floor_sq = 0;
    int floor_points = 0;
    for (const auto& m : d.seen) {
        if (auto f = d.floor.find(m.id); f != d.floor.end()) {
            if (count[m.id] > 1) continue;
            const auto corners = flat_marker_corners(f->second->x, f->second->y, 0, f->second->yaw, f->second->size);
            const auto expected = project_points({corners.begin(), corners.end()}, d.extrinsics, camera_.camera_matrix, camera_.distortion);
            for (int i = 0; i < 4; ++i) {
                const cv::Point2d diff = expected[size_t(i)] - cv::Point2d(m.corners[size_t(i)]);
                floor_sq += diff.dot(diff);
                ++floor_points;
            }
            ++view.floor_markers;
            continue;
        }
        const vehicle::RoofMarker* roof = world_.roof_marker(m.id);
        if (!roof) {
            if (std::find(view.unknown_ids.begin(), view.unknown_ids.end(), m.id) == view.unknown_ids.end()) view.unknown_ids.push_back(m.id);
            continue;
        }
        if (count[m.id] > 1) {
            if (std::find(view.seen_twice.begin(), view.seen_twice.end(), m.id) == view.seen_twice.end()) view.seen_twice.push_back(m.id);
            continue;
        }
        std::array<cv::Vec3d, 4> p;
        bool finite = true;
        for (int i = 0; i < 4; ++i) {
            p[size_t(i)] = on_plane(m.corners[size_t(i)], roof->z);
            finite = finite && std::isfinite(p[size_t(i)][0]);
        }
        bool fits = finite;
        for (int i = 0; i < 4 && fits; ++i) {
            const double side = cv::norm(p[size_t((i + 1) % 4)] - p[size_t(i)]);
            fits = std::abs(side - roof->size) <= 0.25 * roof->size;
        }
        if (!fits) {
            view.misfits.push_back(m.id);
            continue;
        }
        const cv::Vec3d centre = (p[0] + p[1] + p[2] + p[3]) * 0.25;
        const cv::Vec3d x_axis = (p[1] - p[0]) + (p[2] - p[3]);
        LocatedCar car;
        car.vehicle_id = roof->vehicle_id;
        car.marker_id = m.id;
        car.x = centre[0];
        car.y = centre[1];
        car.yaw = std::atan2(x_axis[1], x_axis[0]);
        car.corners = m.corners;
        view.cars.push_back(car);
    }
    std::sort(view.cars.begin(), view.cars.end(), [](const LocatedCar& a, const LocatedCar& b) { return a.vehicle_id < b.vehicle_id; });
    if (floor_points > 0) view.floor_residual_px = std::sqrt(floor_sq / floor_points);
    return view;
}

// ---------------------------------------------------------------------------------------------
// Locating the camera

CameraLocation locate_camera(const Camera& lens, const vehicle::World& world, const cv::Mat& gray, DetectorOptions options)
{
    if (world.floor_markers().size() < 2) {
        throw Error("the world has " + std::to_string(world.floor_markers().size()) +
                    " floor_markers; locating the camera needs at least 2 seen in the image");
    }
    MarkerDetector detector(lens, options);
    std::vector<MarkerObservation> seen;
    detector.detect(gray, seen);
    CameraLocation out;
    std::vector<cv::Point3d> object;
    std::vector<cv::Point2d> image;
    std::map<int, int> count;
    for (const auto& m : seen) ++count[m.id];
    for (const auto& m : seen) {
        const vehicle::FloorMarker* f = nullptr;
        for (const auto& candidate : world.floor_markers()) {
            if (candidate.id == m.id) f = &candidate;
        }
        if (!f) {
            out.unknown.push_back(m.id);
            continue;
        }
        if (count[m.id] > 1) throw Error("floor marker " + std::to_string(m.id) + " is seen " + std::to_string(count[m.id]) + " times in the image");
        const auto corners = flat_marker_corners(f->x, f->y, 0, f->yaw, f->size);
        for (int i = 0; i < 4; ++i) {
            object.emplace_back(corners[size_t(i)]);
            image.emplace_back(m.corners[size_t(i)]);
        }
        out.markers.push_back(m.id);
    }
    std::sort(out.markers.begin(), out.markers.end());
    std::sort(out.unknown.begin(), out.unknown.end());
    if (out.markers.size() < 2) {
        std::string ids;
        for (int id : out.markers) ids += " " + std::to_string(id);
        throw Error("the image shows " + std::to_string(out.markers.size()) + " of the world's floor markers" +
                    (ids.empty() ? "" : " (" + ids.substr(1) + ")") + "; locating the camera needs at least 2");
    }
    // All floor corners lie in one plane, and a camera looking nearly straight down is the case
    // where a plane's two poses are hard to tell apart (a small tilt one way or the other): each
    // of IPPE's solutions and the iterative solver's is refined over every corner by
    // Levenberg-Marquardt, and the one with the camera above the floor that reprojects best wins.
    std::vector<cv::Mat> rvecs, tvecs;
    cv::solvePnPGeneric(object, image, lens.camera_matrix, lens.distortion, rvecs, tvecs, false, cv::SOLVEPNP_IPPE);
    cv::Mat r_iter, t_iter;
    if (cv::solvePnP(object, image, lens.camera_matrix, lens.distortion, r_iter, t_iter, false, cv::SOLVEPNP_ITERATIVE)) {
        rvecs.push_back(r_iter);
        tvecs.push_back(t_iter);
    }
    double best = std::numeric_limits<double>::infinity();
    for (size_t i = 0; i < rvecs.size(); ++i) {
        cv::Mat rvec = rvecs[i].clone(), tvec = tvecs[i].clone();
        cv::solvePnPRefineLM(object, image, lens.camera_matrix, lens.distortion, rvec, tvec);
        cv::Matx33d map_to_camera;
        cv::Rodrigues(rvec, map_to_camera);
        const cv::Vec3d centre = -(map_to_camera.t() * cv::Vec3d(tvec.ptr<double>()));
        if (centre[2] <= 0) continue;
        std::vector<cv::Point2d> back;
        cv::projectPoints(object, rvec, tvec, lens.camera_matrix, lens.distortion, back);
        double sq = 0;
        for (size_t k = 0; k < back.size(); ++k) sq += (back[k] - image[k]).dot(back[k] - image[k]);
        const double rms = std::sqrt(sq / double(back.size()));
        if (rms >= best) continue;
        best = rms;
        out.pose.rotation = map_to_camera.t();
        out.pose.position = centre;
        out.pose.residual_px = rms;
    }
    if (!std::isfinite(best)) throw Error("no camera pose above the floor fits the floor markers seen");
    return out;
}

}  // namespace cpm::aruco
