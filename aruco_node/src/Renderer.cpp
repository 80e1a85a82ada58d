#include <cpm/aruco/Renderer.hpp>

#include "MarkerPainter.hpp"

#include <cpm/Error.hpp>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <optional>

namespace cpm::aruco {

struct Renderer::Impl
{
    explicit Impl(const RenderOptions& options) : painter(options) {}
    MarkerPainter painter;
};

Renderer::Renderer(vehicle::World world, Camera camera, RenderOptions options)
    : world_(std::move(world)), camera_(std::move(camera)), options_(std::move(options)), impl_(std::make_unique<Impl>(options_))
{
    for (const auto& m : world_.markers()) impl_->painter.check_id(m.id, "the map");
}

Renderer::~Renderer() = default;

cv::Mat Renderer::render(const vehicle::Pose& car, std::vector<RenderedMarker>* truth)
{
    cv::Mat frame;
    render(car, frame, truth);
    return frame;
}

namespace {

/// A marker the camera sees, in the car frame.
struct Visible
{
    const vehicle::Marker* marker;
    cv::Vec3d centre_car;
    double normal_yaw;
    double distance;
};

/// Wall above the horizon, floor below (the camera does not roll).
void draw_background(const Camera& camera, const RenderOptions& options, cv::Mat& frame)
{
    const int h = camera.height;
    const cv::Vec3d ahead = camera.car_from_camera_rotation().t() * cv::Vec3d(std::cos(camera.mount.yaw), std::sin(camera.mount.yaw), 0);
    const double horizon = ahead[2] > 1e-9 ? camera.camera_matrix(1, 2) + camera.fy() * ahead[1] / ahead[2] : (camera.mount.pitch > 0 ? -1 : h);
    const int split = std::clamp(int(std::lround(horizon)), 0, h);
    frame.rowRange(0, split).setTo(options.wall_grey);
    frame.rowRange(split, h).setTo(options.floor_grey);
}

/// The world's markers facing the camera and hidden by no wall, far ones first.
std::vector<Visible> visible_markers(const vehicle::World& world, const Camera& camera, const vehicle::Pose& car)
{
    const double c = std::cos(car.yaw), s = std::sin(car.yaw);
    const cv::Vec3d cam_car(camera.mount.x, camera.mount.y, camera.mount.z);
    const double cam_wx = car.x + c * cam_car[0] - s * cam_car[1], cam_wy = car.y + s * cam_car[0] + c * cam_car[1];
    std::vector<Visible> visible;
    for (const auto& m : world.markers()) {
        const double dx = m.x - car.x, dy = m.y - car.y;
        const cv::Vec3d centre(c * dx + s * dy, -s * dx + c * dy, m.z);
        const double yaw = m.yaw - car.yaw;
        const cv::Vec3d normal(std::cos(yaw), std::sin(yaw), 0);
        if (normal.dot(cam_car - centre) <= 0) continue;  // facing away
        // Hidden by a wall: the sight lines to both vertical edges, stopped 1 cm short.
        const double half = m.size / 2;
        bool hidden = false;
        for (double side : {-1.0, 1.0}) {
            const double ex = m.x + side * half * -std::sin(m.yaw), ey = m.y + side * half * std::cos(m.yaw);
            const double len = std::hypot(ex - cam_wx, ey - cam_wy);
            if (len < 0.02) continue;
            const double k = (len - 0.01) / len;
            vehicle::Segment sight{cam_wx, cam_wy, cam_wx + k * (ex - cam_wx), cam_wy + k * (ey - cam_wy)};
            if (world.wall_hit({sight})) hidden = true;
        }
        if (hidden) continue;
        visible.push_back({&m, centre, yaw, cv::norm(centre - cam_car)});
    }
    std::sort(visible.begin(), visible.end(), [](const Visible& a, const Visible& b) { return a.distance > b.distance; });
    return visible;
}

/// One standing marker drawn into the frame; what was drawn, or nothing when it is behind the
/// camera or too small.
std::optional<RenderedMarker> draw_standing(MarkerPainter& painter, const Camera& camera, const Visible& v, cv::Mat& frame)
{
    const auto& m = *v.marker;
    const cv::Vec3d right(-std::sin(v.normal_yaw), std::cos(v.normal_yaw), 0), up(0, 0, 1);
    // The black square's corners and the quiet zone's (one cell wider on each side).
    auto corners_at = [&](double half) {
        return std::array<cv::Vec3d, 4>{camera.to_camera(v.centre_car - half * right + half * up),
                                        camera.to_camera(v.centre_car + half * right + half * up),
                                        camera.to_camera(v.centre_car + half * right - half * up),
                                        camera.to_camera(v.centre_car - half * right - half * up)};
    };
    const auto black = corners_at(m.size / 2);
    const auto outer = corners_at(m.size / 2 * painter.quiet_zone_scale());
    bool in_front = true;
    for (const auto& p : outer) in_front = in_front && p[2] > 0.05;
    if (!in_front) return std::nullopt;  // projectPoints would mirror points behind the camera

    std::vector<cv::Point3d> object(black.begin(), black.end());
    object.insert(object.end(), outer.begin(), outer.end());
    std::vector<cv::Point2d> image;
    cv::projectPoints(object, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), camera.camera_matrix, camera.distortion, image);
    const std::array<cv::Point2d, 4> corners{image[0], image[1], image[2], image[3]};
    if (!painter.paint(frame, m.id, corners, {image[4], image[5], image[6], image[7]})) return std::nullopt;
    const QuadSize size = quad_size(corners);
    RenderedMarker t;
    t.id = m.id;
    for (size_t i = 0; i < 4; ++i) t.corners[i] = corners[i];
    t.x = v.centre_car[0];
    t.y = v.centre_car[1];
    t.z = v.centre_car[2];
    t.yaw = std::remainder(v.normal_yaw, 2 * M_PI);
    t.distance = v.distance;
    t.side_px = size.side;
    t.shortest_side_px = size.shortest;
    t.whole_in_view = whole_in_view(corners, camera.width, camera.height);
    return t;
}

}  // namespace

void Renderer::render(const vehicle::Pose& car, cv::Mat& frame, std::vector<RenderedMarker>* truth)
{
    frame.create(camera_.height, camera_.width, CV_8UC1);
    draw_background(camera_, options_, frame);
    if (truth) truth->clear();
    for (const auto& v : visible_markers(world_, camera_, car)) {
        const auto drawn = draw_standing(impl_->painter, camera_, v, frame);
        if (drawn && truth) truth->push_back(*drawn);
    }
    impl_->painter.sensor(frame);
}

}  // namespace cpm::aruco
