#include <cpm/vehicle/BridgeCore.hpp>

#include <algorithm>
#include <cmath>

namespace cpm::vehicle {

const char* to_string(ActiveCommand command)
{
    switch (command) {
    case ActiveCommand::None: return "none";
    case ActiveCommand::Stopped: return "stop_request";
    case ActiveCommand::Direct: return "direct";
    case ActiveCommand::SpeedCurvature: return "speed_curvature";
    case ActiveCommand::Trajectory: return "trajectory";
    case ActiveCommand::PathTracking: return "path_tracking";
    }
    return "?";
}

BridgeCore::BridgeCore(uint8_t vehicle_id, const Calibration& calibration, Pose start)
    : vehicle_id_(vehicle_id), c_(calibration), speed_controller_(calibration), pose_(start)
{
}

void BridgeCore::link_restarted()
{
    last_steps_.reset();
    last_tick_.reset();
    offsets_.clear();
    tick_epoch_ms_ = 0;
}

uint64_t BridgeCore::measured_time(uint32_t tick, uint64_t received_ns)
{
    if (last_tick_ && tick < *last_tick_) {
        if (*last_tick_ - tick > 0x80000000u) {
            tick_epoch_ms_ += 0x100000000ull;  // wrapped
        } else {
            offsets_.clear();  // the controller restarted: its clock began anew
            tick_epoch_ms_ = 0;
        }
    }
    const uint64_t tick_ns = (tick_epoch_ms_ + tick) * 1'000'000ull;
    const int64_t offset = int64_t(received_ns) - int64_t(tick_ns);
    // A monotonic queue: the front is the smallest offset within the window.
    while (!offsets_.empty() && offsets_.back().second >= offset) offsets_.pop_back();
    offsets_.emplace_back(received_ns, offset);
    while (offsets_.front().first + 5'000'000'000ull < received_ns) offsets_.pop_front();
    return uint64_t(int64_t(tick_ns) + offsets_.front().second);
}

void BridgeCore::dead_reckon(const StatePacket& packet, uint64_t t_ns)
{
    double imu_yaw = packet.imu_yaw_e4 * 1e-4;
    if (!last_steps_) {
        // New link: keep the pose, rebase odometer and IMU heading on this packet.
        yaw_offset_ = wrap_angle(pose_.yaw - imu_yaw);
    } else {
        double ds = double(packet.odometer_steps - *last_steps_) / c_.ticks_per_metre;
        double yaw_new = wrap_angle(imu_yaw + yaw_offset_);
        double yaw_mid = pose_.yaw + 0.5 * wrap_angle(yaw_new - pose_.yaw);
        pose_.x += ds * std::cos(yaw_mid);
        pose_.y += ds * std::sin(yaw_mid);
        pose_.yaw = yaw_new;
        distance_ += ds;
    }
    last_steps_ = packet.odometer_steps;
    history_.push_back({t_ns, pose_});
    while (!history_.empty() && history_.front().t_ns + 2'000'000'000ull < t_ns) history_.pop_front();
}

void BridgeCore::on_observation(const Pose& observed, uint64_t t_ns)
{
    // The estimate at the observation's time (the newest one not after it).
    auto it = std::upper_bound(history_.begin(), history_.end(), t_ns,
                               [](uint64_t t, const Estimate& e) { return t < e.t_ns; });
    Pose then = it == history_.begin() ? pose_ : (it - 1)->pose;
    double dx = observed.x - then.x, dy = observed.y - then.y, dyaw = wrap_angle(observed.yaw - then.yaw);
    pose_.x += dx;
    pose_.y += dy;
    pose_.yaw = wrap_angle(pose_.yaw + dyaw);
    yaw_offset_ = wrap_angle(yaw_offset_ + dyaw);
    for (auto& e : history_) {
        e.pose.x += dx;
        e.pose.y += dy;
        e.pose.yaw = wrap_angle(e.pose.yaw + dyaw);
    }
}

bool BridgeCore::fresh(uint64_t age_ns, uint64_t create_ns, const CommandInputs& commands) const
{
    if (double(age_ns) * 1e-9 >= c_.command_timeout) return false;
    // A stop request holds until a command newer than it arrives.
    return !commands.stop_request_ns || create_ns > *commands.stop_request_ns;
}

BridgeCore::Actuation BridgeCore::drive(const MotionRequest& request, double speed, double dt)
{
    Actuation a;
    a.steering = steering_for_curvature(c_, request.curvature);
    if (request.speed <= 0 && std::abs(speed) < 0.05) {
        speed_controller_.reset();
        return a;  // brake: nothing to drive to
    }
    a.throttle = speed_controller_.update(request.speed, speed, dt);
    a.brake = false;
    return a;
}

BridgeCore::Actuation BridgeCore::choose(const CommandInputs& in, uint64_t t_ns, double speed, double dt,
                                         ActiveCommand& active)
{
    auto is_fresh = [&](const auto& result) {
        return result.valid && fresh(result.age_ns, result.sample.header().create_stamp().nanoseconds(), in);
    };
    if (is_fresh(in.direct)) {
        active = ActiveCommand::Direct;
        Actuation a;
        a.throttle = std::clamp(in.direct.sample.motor_throttle(), -1.0, 1.0);
        a.steering = std::clamp(in.direct.sample.steering_servo(), -1.0, 1.0);
        a.brake = false;
        return a;
    }
    if (is_fresh(in.speed_curvature)) {
        active = ActiveCommand::SpeedCurvature;
        return drive({in.speed_curvature.sample.speed(), in.speed_curvature.sample.curvature()}, speed, dt);
    }
    if (is_fresh(in.trajectory)) {
        active = ActiveCommand::Trajectory;
        uint64_t t_ref = t_ns + static_cast<uint64_t>(c_.lookahead_time * 1e9);
        if (auto reference = interpolate_trajectory(in.trajectory.sample.trajectory_points(), t_ref)) {
            return drive(track_trajectory(c_, *reference, pose_), speed, dt);
        }
        return drive({}, speed, dt);  // the trajectory does not cover now: stop
    }
    if (is_fresh(in.path_tracking)) {
        active = ActiveCommand::PathTracking;
        const auto& command = in.path_tracking.sample;
        if (auto request = track_path(c_, command.path(), command.speed(), pose_, speed)) {
            return drive(*request, speed, dt);
        }
        return drive({}, speed, dt);
    }
    active = in.stop_request_ns ? ActiveCommand::Stopped : ActiveCommand::None;
    speed_controller_.reset();
    return {};
}

CommandPacket BridgeCore::to_packet(const Actuation& a)
{
    CommandPacket packet;
    packet.tick = ++command_tick_;
    packet.vehicle_id = vehicle_id_;
    if (a.brake) {
        packet.motor_mode = MotorMode::Brake;
    } else {
        packet.motor_mode = a.throttle >= 0 ? MotorMode::Forward : MotorMode::Reverse;
        packet.motor_pwm = static_cast<uint16_t>(std::lround(std::min(std::abs(a.throttle), 1.0) * 1000));
    }
    double servo = c_.servo_centre_us + a.steering * c_.servo_range_us;
    packet.servo_us = static_cast<uint16_t>(std::lround(std::clamp(servo, 0.0, 65535.0)));
    return packet;
}

BridgeCycle BridgeCore::on_state_packet(const StatePacket& packet, uint64_t t_ns, const CommandInputs& commands)
{
    double dt = last_tick_ ? std::clamp((packet.tick - *last_tick_) * 1e-3, 1e-3, 0.1) : 0.02;
    BridgeCycle out;
    out.measured_ns = measured_time(packet.tick, t_ns);
    last_tick_ = packet.tick;
    dead_reckon(packet, t_ns);
    double speed = packet.speed_mm_s * 1e-3;

    Actuation a = choose(commands, t_ns, speed, dt, out.active);
    if (out.active != last_active_) speed_controller_.reset();
    last_active_ = out.active;
    out.command = to_packet(a);

    VehicleState& s = out.state;
    s.vehicle_id(vehicle_id_);
    s.pose().x(pose_.x);
    s.pose().y(pose_.y);
    s.pose().yaw(pose_.yaw);
    s.odometer_distance(distance_);
    s.imu_acceleration_forward(packet.accel_forward_mm_s2 * 1e-3);
    s.imu_acceleration_left(packet.accel_left_mm_s2 * 1e-3);
    s.imu_acceleration_up(packet.accel_up_mm_s2 * 1e-3);
    s.imu_yaw(packet.imu_yaw_e4 * 1e-4);
    s.imu_yaw_rate(packet.imu_yaw_rate_e3 * 1e-3);
    s.speed(speed);
    s.battery_voltage(packet.battery_mv * 1e-3);
    s.motor_current(packet.motor_current_ma * 1e-3);
    s.motor_throttle(a.brake ? 0.0 : a.throttle);
    s.steering_servo(a.steering);

    RangeSensors& r = out.ranges;
    r.vehicle_id(vehicle_id_);
    r.front(packet.us_front_mm * 1e-3);
    r.left(packet.us_left_mm * 1e-3);
    r.right(packet.us_right_mm * 1e-3);
    r.hall_distance(distance_);
    return out;
}

}  // namespace cpm::vehicle
