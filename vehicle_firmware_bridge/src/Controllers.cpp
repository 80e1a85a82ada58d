#include <cpm/vehicle/Controllers.hpp>

#include "json_members.hpp"

#include <algorithm>
#include <cmath>

namespace cpm::vehicle {

Calibration Calibration::load(const std::string& path)
{
    return parse(read_text_file(path, "calibration file"), path);
}

Calibration Calibration::parse(const std::string& json_text, const std::string& source)
{
    Calibration c;
    JsonMembers members(json_text, source);
    members.number("ticks_per_metre", c.ticks_per_metre, 1);
    members.number("servo_centre_us", c.servo_centre_us, 500, 2500);
    members.number("servo_range_us", c.servo_range_us, -1000, 1000);
    members.number("max_steering_angle", c.max_steering_angle, 0.01, 1.5);
    members.number("wheelbase", c.wheelbase, 0.01);
    members.number("throttle_per_speed", c.throttle_per_speed, 0);
    members.number("speed_kp", c.speed_kp, 0);
    members.number("speed_ki", c.speed_ki, 0);
    members.number("speed_integral_limit", c.speed_integral_limit, 0, 1);
    members.number("trajectory_kx", c.trajectory_kx, 0);
    members.number("trajectory_ky", c.trajectory_ky, 0);
    members.number("trajectory_ktheta", c.trajectory_ktheta, 0);
    members.number("lookahead_time", c.lookahead_time, 0, 1);
    members.number("path_lookahead_min", c.path_lookahead_min, 0.01);
    members.number("path_lookahead_per_speed", c.path_lookahead_per_speed, 0);
    members.number("path_stop_deceleration", c.path_stop_deceleration, 0.01);
    members.number("command_timeout", c.command_timeout, 0.01);
    members.number("publish_delay", c.publish_delay, 0, 1);
    members.number("max_speed", c.max_speed, 0.01, 100);
    members.number("battery_min_voltage", c.battery_min_voltage, 0);
    members.number("battery_max_voltage", c.battery_max_voltage, 0);
    members.finish();
    if (c.servo_range_us == 0) throw Error(source + ": servo_range_us must not be 0");
    if (c.battery_min_voltage >= c.battery_max_voltage)
        throw Error(source + ": battery_min_voltage must be below battery_max_voltage");
    return c;
}

double SpeedController::update(double v_ref, double v_measured, double dt)
{
    double error = v_ref - v_measured;
    double limit = c_.speed_ki > 0 ? c_.speed_integral_limit / c_.speed_ki : 0;
    if (!std::isfinite(error) || !std::isfinite(dt)) {
        // Never let a non-finite input into the integral: it would stay NaN for good.
        integral_ = 0;
        return 0;
    }
    integral_ = std::clamp(integral_ + error * dt, -limit, limit);
    double throttle = v_ref * c_.throttle_per_speed + c_.speed_kp * error + c_.speed_ki * integral_;
    return std::clamp(throttle, -1.0, 1.0);
}

double steering_for_curvature(const Calibration& calibration, double curvature)
{
    double angle = std::atan(curvature * calibration.wheelbase);
    return std::clamp(angle / calibration.max_steering_angle, -1.0, 1.0);
}

std::optional<TrajectoryReference> interpolate_trajectory(const std::vector<TrajectoryPoint>& points, uint64_t t_ns)
{
    if (points.size() < 2) return std::nullopt;
    auto later = std::upper_bound(points.begin(), points.end(), t_ns,
                                  [](uint64_t t, const TrajectoryPoint& p) { return t < p.t().nanoseconds(); });
    if (later == points.begin()) return std::nullopt;
    if (later == points.end()) {
        if (points.back().t().nanoseconds() != t_ns) return std::nullopt;
        later = points.end() - 1;
    }
    const TrajectoryPoint& a = *(later - 1);
    const TrajectoryPoint& b = *later;
    double tau = double(b.t().nanoseconds() - a.t().nanoseconds()) * 1e-9;
    if (tau <= 0) return std::nullopt;
    double s = double(t_ns - a.t().nanoseconds()) * 1e-9 / tau;
    double s2 = s * s, s3 = s2 * s;
    // Hermite basis functions and their first and second derivatives with respect to s.
    double h00 = 2 * s3 - 3 * s2 + 1, h10 = s3 - 2 * s2 + s, h01 = -2 * s3 + 3 * s2, h11 = s3 - s2;
    double d00 = 6 * s2 - 6 * s, d10 = 3 * s2 - 4 * s + 1, d01 = -6 * s2 + 6 * s, d11 = 3 * s2 - 2 * s;
    double dd00 = 12 * s - 6, dd10 = 6 * s - 4, dd01 = -12 * s + 6, dd11 = 6 * s - 2;
    auto blend = [&](double p0, double v0, double p1, double v1, double k00, double k10, double k01, double k11) {
        return k00 * p0 + k10 * tau * v0 + k01 * p1 + k11 * tau * v1;
    };
    TrajectoryReference r;
    r.x = blend(a.px(), a.vx(), b.px(), b.vx(), h00, h10, h01, h11);
    r.y = blend(a.py(), a.vy(), b.py(), b.vy(), h00, h10, h01, h11);
    r.vx = blend(a.px(), a.vx(), b.px(), b.vx(), d00, d10, d01, d11) / tau;
    r.vy = blend(a.py(), a.vy(), b.py(), b.vy(), d00, d10, d01, d11) / tau;
    r.ax = blend(a.px(), a.vx(), b.px(), b.vx(), dd00, dd10, dd01, dd11) / (tau * tau);
    r.ay = blend(a.py(), a.vy(), b.py(), b.vy(), dd00, dd10, dd01, dd11) / (tau * tau);
    return r;
}

namespace {

double max_curvature(const Calibration& c) { return std::tan(c.max_steering_angle) / c.wheelbase; }

}  // namespace

MotionRequest track_trajectory(const Calibration& c, const TrajectoryReference& r, const Pose& pose)
{
    double v_r = std::hypot(r.vx, r.vy);
    double dx = r.x - pose.x, dy = r.y - pose.y;
    double cos_yaw = std::cos(pose.yaw), sin_yaw = std::sin(pose.yaw);
    double e_x = cos_yaw * dx + sin_yaw * dy;
    double e_y = -sin_yaw * dx + cos_yaw * dy;
    if (v_r < 1e-3) return {std::max(0.0, c.trajectory_kx * e_x), 0.0};
    double e_theta = wrap_angle(std::atan2(r.vy, r.vx) - pose.yaw);
    double omega_r = (r.vx * r.ay - r.vy * r.ax) / (v_r * v_r);
    double v = v_r * std::cos(e_theta) + c.trajectory_kx * e_x;
    double omega = omega_r + v_r * (c.trajectory_ky * e_y + c.trajectory_ktheta * std::sin(e_theta));
    double k_max = max_curvature(c);
    double curvature = std::clamp(omega / std::max(v, 0.1), -k_max, k_max);
    return {std::max(v, 0.0), curvature};
}

std::optional<MotionRequest> track_path(const Calibration& c, const std::vector<PathPoint>& path, double speed,
                                        const Pose& pose, double measured_speed)
{
    if (path.size() < 2) return std::nullopt;
    // Arc length of each point along the polyline, and the closest point to the car.
    std::vector<double> s(path.size(), 0.0);
    for (size_t i = 1; i < path.size(); ++i) {
        s[i] = s[i - 1] + std::hypot(path[i].pose().x() - path[i - 1].pose().x(), path[i].pose().y() - path[i - 1].pose().y());
    }
    double best_d2 = INFINITY, s_closest = 0;
    for (size_t i = 0; i + 1 < path.size(); ++i) {
        double ax = path[i].pose().x(), ay = path[i].pose().y();
        double ex = path[i + 1].pose().x() - ax, ey = path[i + 1].pose().y() - ay;
        double len2 = ex * ex + ey * ey;
        double u = len2 > 0 ? std::clamp(((pose.x - ax) * ex + (pose.y - ay) * ey) / len2, 0.0, 1.0) : 0.0;
        double px = ax + u * ex - pose.x, py = ay + u * ey - pose.y;
        if (px * px + py * py < best_d2) {
            best_d2 = px * px + py * py;
            s_closest = s[i] + u * (s[i + 1] - s[i]);
        }
    }
    double lookahead = std::max(c.path_lookahead_min, c.path_lookahead_per_speed * std::abs(measured_speed));
    double s_target = s_closest + lookahead;
    // The point at s_target; past the end, the last segment continued.
    size_t i = 0;
    while (i + 2 < path.size() && s[i + 1] < s_target) ++i;
    double seg = s[i + 1] - s[i];
    double u = seg > 0 ? (s_target - s[i]) / seg : 0.0;
    double tx = path[i].pose().x() + u * (path[i + 1].pose().x() - path[i].pose().x());
    double ty = path[i].pose().y() + u * (path[i + 1].pose().y() - path[i].pose().y());
    double dx = tx - pose.x, dy = ty - pose.y;
    double alpha = wrap_angle(std::atan2(dy, dx) - pose.yaw);
    double distance = std::max(std::hypot(dx, dy), 1e-3);
    double k_max = max_curvature(c);
    double curvature = std::clamp(2 * std::sin(alpha) / distance, -k_max, k_max);

    double remaining = s.back() - s_closest;
    double v = remaining < 0.01 ? 0.0 : std::min(speed, std::sqrt(2 * c.path_stop_deceleration * remaining));
    return MotionRequest{v, curvature};
}

}  // namespace cpm::vehicle
