#pragma once
#include <cpm/vehicle/Calibration.hpp>
#include <cpm/vehicle/VehicleModel.hpp>

#include <VehicleCommandPathTracking.h>
#include <VehicleCommandTrajectory.h>

#include <cstdint>
#include <optional>
#include <vector>

/// The on-board controllers of vehicle_bridge (cpm_lab's vehicle controller, simplified).
namespace cpm::vehicle {

/// Speed PI with feed-forward: throttle = v_ref * throttle_per_speed + kp e + ki ∫e.
class SpeedController
{
public:
    explicit SpeedController(const Calibration& calibration) : c_(calibration) {}
    /// Throttle in -1..1 for the reference speed (m/s) given the measured one; dt in s.
    double update(double v_ref, double v_measured, double dt);
    void reset() { integral_ = 0; }

private:
    Calibration c_;
    double integral_ = 0;
};

/// steering_servo (-1..1) for a path curvature (1/m), from the bicycle model:
/// angle = atan(curvature * wheelbase), clamped at max_steering_angle.
double steering_for_curvature(const Calibration& calibration, double curvature);

/// A speed and a curvature for the speed and steering controllers.
struct MotionRequest
{
    double speed = 0;      ///< m/s
    double curvature = 0;  ///< 1/m
};

/// Position, velocity and acceleration of a trajectory at one time.
struct TrajectoryReference
{
    double x = 0, y = 0, vx = 0, vy = 0, ax = 0, ay = 0;
};

/// Cubic Hermite interpolation between the two trajectory points around t_ns (points sorted
/// by time); nullopt when t_ns lies outside the trajectory.
std::optional<TrajectoryReference> interpolate_trajectory(const std::vector<TrajectoryPoint>& points, uint64_t t_ns);

/// Kanayama's tracking law (1990): v = v_r cos(e_θ) + kx e_x,
/// ω = ω_r + v_r (ky e_y + kθ sin e_θ), curvature = ω / v.
MotionRequest track_trajectory(const Calibration& calibration, const TrajectoryReference& reference, const Pose& pose);

/// Pure pursuit along the path (poses in order of s) at the commanded speed, slowing to stop
/// at its end; nullopt for a path with fewer than two points.
std::optional<MotionRequest> track_path(const Calibration& calibration, const std::vector<PathPoint>& path,
                                        double speed, const Pose& pose, double measured_speed);

}  // namespace cpm::vehicle
