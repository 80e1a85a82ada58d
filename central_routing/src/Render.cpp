#include <cpm/routing/Render.hpp>

#include <cpm/Error.hpp>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <fstream>
#include <sstream>

namespace cpm::routing {
namespace {

constexpr double kScale = 200;   // px per metre
constexpr double kBorder = 0.3;  // m around the lanes

/// What is drawn, in metres; SVG and PNG are two ways of putting it on a page.
struct Scene
{
    double x0 = 1e9, y0 = 1e9, x1 = -1e9, y1 = -1e9;
    std::vector<std::vector<Vec2>> lanes, arrows, zones, cars;
    std::vector<std::pair<Vec2, std::string>> labels;
    double width_px() const { return (x1 - x0) * kScale; }
    double height_px() const { return (y1 - y0) * kScale; }
    cv::Point2d px(const Vec2& p) const { return {(p.x() - x0) * kScale, (y1 - p.y()) * kScale}; }
};

Scene make_scene(const ConflictTable& table, const std::vector<DrawnCar>& cars)
{
    const LaneGraph& g = table.graph();
    Scene scene;
    for (const auto& e : g.edges) {
        scene.lanes.push_back(e.points);
        for (const auto& p : e.points) {
            scene.x0 = std::min(scene.x0, p.x()), scene.y0 = std::min(scene.y0, p.y());
            scene.x1 = std::max(scene.x1, p.x()), scene.y1 = std::max(scene.y1, p.y());
        }
        // An arrowhead half way along the lane.
        const Pose mid = g.pose_at(size_t(&e - g.edges.data()), e.length() / 2);
        const Vec2 tip(mid.x, mid.y), back(-std::cos(mid.yaw), -std::sin(mid.yaw)), side(-back.y(), back.x());
        scene.arrows.push_back({tip + 0.06 * back + 0.035 * side, tip, tip + 0.06 * back - 0.035 * side});
    }
    scene.x0 -= kBorder, scene.y0 -= kBorder, scene.x1 += kBorder, scene.y1 += kBorder;
    for (const auto& z : table.zones()) {
        std::vector<cv::Point2f> points, hull;
        for (uint32_t i : z.samples) points.emplace_back(float(table.pose(i).x), float(table.pose(i).y));
        cv::convexHull(points, hull);
        std::vector<Vec2> polygon;
        for (const auto& p : hull) polygon.emplace_back(p.x, p.y);
        scene.zones.push_back(polygon);
    }
    for (const auto& n : g.nodes) scene.labels.push_back({n.p, std::to_string(n.id)});
    const Footprint& f = table.options().footprint;
    for (const auto& car : cars) {
        const Vec2 c(car.pose.x, car.pose.y), u(std::cos(car.pose.yaw), std::sin(car.pose.yaw)), n(-u.y(), u.x());
        const double front = f.length - f.rear_overhang, back = f.rear_overhang, w = f.width / 2;
        scene.cars.push_back({c + front * u + w * n, c - back * u + w * n, c - back * u - w * n, c + front * u - w * n});
        scene.labels.push_back({c + (front / 2) * u, "car " + std::to_string(car.id)});
    }
    return scene;
}

std::string points_attribute(const Scene& s, const std::vector<Vec2>& points)
{
    std::ostringstream out;
    for (const auto& p : points) out << s.px(p).x << ',' << s.px(p).y << ' ';
    return out.str();
}

void write_svg(const Scene& s, const std::string& path)
{
    std::ofstream out(path);
    if (!out) throw cpm::Error(path + ": cannot be written");
    out << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << s.width_px() << "\" height=\"" << s.height_px()
        << "\" font-family=\"sans-serif\" font-size=\"11\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
    for (const auto& z : s.zones) {
        out << "<polygon points=\"" << points_attribute(s, z) << "\" fill=\"#e4572e\" fill-opacity=\"0.25\" stroke=\"#e4572e\"/>\n";
    }
    for (const auto& l : s.lanes) {
        out << "<polyline points=\"" << points_attribute(s, l) << "\" fill=\"none\" stroke=\"#33658a\" stroke-width=\"2\"/>\n";
    }
    for (const auto& a : s.arrows) out << "<polygon points=\"" << points_attribute(s, a) << "\" fill=\"#33658a\"/>\n";
    for (const auto& c : s.cars) {
        out << "<polygon points=\"" << points_attribute(s, c) << "\" fill=\"#f6ae2d\" fill-opacity=\"0.85\" stroke=\"black\"/>\n";
    }
    for (const auto& [p, text] : s.labels) {
        out << "<circle cx=\"" << s.px(p).x << "\" cy=\"" << s.px(p).y << "\" r=\"3\" fill=\"black\"/>\n";
        out << "<text x=\"" << s.px(p).x + 4 << "\" y=\"" << s.px(p).y - 4 << "\">" << text << "</text>\n";
    }
    out << "</svg>\n";
    if (!out) throw cpm::Error(path + ": cannot be written");
}

void write_png(const Scene& s, const std::string& path)
{
    cv::Mat image(int(std::ceil(s.height_px())), int(std::ceil(s.width_px())), CV_8UC3, cv::Scalar(255, 255, 255));
    auto poly = [&](const std::vector<Vec2>& points) {
        std::vector<cv::Point> out;
        for (const auto& p : points) out.emplace_back(cv::Point(int(std::lround(s.px(p).x)), int(std::lround(s.px(p).y))));
        return out;
    };
    cv::Mat overlay = image.clone();
    for (const auto& z : s.zones) cv::fillPoly(overlay, std::vector<std::vector<cv::Point>>{poly(z)}, cv::Scalar(46, 87, 228));
    cv::addWeighted(overlay, 0.25, image, 0.75, 0, image);
    for (const auto& l : s.lanes) cv::polylines(image, poly(l), false, cv::Scalar(138, 101, 51), 2, cv::LINE_AA);
    for (const auto& a : s.arrows) cv::fillPoly(image, std::vector<std::vector<cv::Point>>{poly(a)}, cv::Scalar(138, 101, 51), cv::LINE_AA);
    for (const auto& c : s.cars) {
        cv::fillPoly(image, std::vector<std::vector<cv::Point>>{poly(c)}, cv::Scalar(45, 174, 246), cv::LINE_AA);
        cv::polylines(image, poly(c), true, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
    }
    for (const auto& [p, text] : s.labels) {
        const cv::Point at(int(s.px(p).x), int(s.px(p).y));
        cv::circle(image, at, 3, cv::Scalar(0, 0, 0), cv::FILLED, cv::LINE_AA);
        cv::putText(image, text, at + cv::Point(4, -4), cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
    }
    if (!cv::imwrite(path, image)) throw cpm::Error(path + ": cannot be written");
}

}  // namespace

void render_lane_graph(const ConflictTable& table, const std::string& path, const std::vector<DrawnCar>& cars)
{
    const auto dot = path.rfind('.');
    const std::string ending = dot == std::string::npos ? "" : path.substr(dot + 1);
    if (ending != "svg" && ending != "png") throw cpm::Error(path + ": the drawing's name must end in .svg or .png");
    const Scene scene = make_scene(table, cars);
    if (ending == "svg") {
        write_svg(scene, path);
    } else {
        write_png(scene, path);
    }
}

}  // namespace cpm::routing
