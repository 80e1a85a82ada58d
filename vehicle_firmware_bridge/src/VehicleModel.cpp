#include <cpm/vehicle/VehicleModel.hpp>

#include <cpm/CommandLine.hpp>
#include <cpm/Error.hpp>

#include "json_members.hpp"

#include <algorithm>
#include <cmath>

namespace cpm::vehicle {

VehicleParameters VehicleParameters::load(const std::string& path)
{
    return parse(read_text_file(path, "vehicle parameter file"), path);
}

VehicleParameters VehicleParameters::parse(const std::string& json_text, const std::string& source)
{
    VehicleParameters p;
    JsonMembers members(json_text, source);
    members.number("wheelbase", p.wheelbase, 0.01);
    members.number("max_steering_angle", p.max_steering_angle, 0.01);
    members.number("max_speed", p.max_speed, 0.01);
    members.number("speed_time_constant", p.speed_time_constant, 0.001);
    members.number("brake_time_constant", p.brake_time_constant, 0.001);
    members.number("steering_time_constant", p.steering_time_constant, 0.001);
    members.number("input_delay", p.input_delay, 0);
    members.number("ticks_per_metre", p.ticks_per_metre, 1);
    members.number("length", p.length, 0.01);
    members.number("width", p.width, 0.01);
    members.number("rear_overhang", p.rear_overhang, 0);
    members.number("battery_full", p.battery_full, 0);
    members.number("battery_capacity", p.battery_capacity, 1);
    members.number("battery_internal_resistance", p.battery_internal_resistance, 0);
    members.number("idle_current", p.idle_current, 0);
    members.number("current_per_speed", p.current_per_speed, 0);
    members.number("imu_yaw_rate_noise", p.imu_yaw_rate_noise, 0);
    members.number("imu_acceleration_noise", p.imu_acceleration_noise, 0);
    members.number("ultrasonic_min_range", p.ultrasonic_min_range, 0);
    members.number("ultrasonic_max_range", p.ultrasonic_max_range, 0.05);
    members.number("ultrasonic_noise", p.ultrasonic_noise, 0);
    members.number("watchdog_timeout", p.watchdog_timeout, 0.01);
    members.number("physics_rate", p.physics_rate, 200);
    members.number("state_rate", p.state_rate, 1);
    members.number("observation_noise", p.observation_noise, 0);
    members.number("observation_dropout", p.observation_dropout, 0, 1);
    const char* names[] = {"front", "left", "right"};
    for (size_t i = 0; i < 3; ++i) {
        members.triple(std::string("ultrasonic_") + names[i], p.ultrasonic[i].x, p.ultrasonic[i].y, p.ultrasonic[i].yaw);
    }
    members.require(p.physics_rate >= p.state_rate, "physics_rate must be >= state_rate");
    members.require(p.ultrasonic_min_range < p.ultrasonic_max_range, "ultrasonic_min_range must be < ultrasonic_max_range");
    members.finish();
    return p;
}

Pose parse_pose(const std::string& flag, const std::string& text)
{
    auto items = cli::split_list(flag, text);
    if (items.size() != 3) throw cli::UsageError(flag + ": expected X,Y,YAW, got '" + text + "'");
    return {cli::parse_number(flag, items[0], -1e6, 1e6), cli::parse_number(flag, items[1], -1e6, 1e6),
            cli::parse_number(flag, items[2], -10, 10)};
}

std::vector<Pose> parse_poses(const std::string& flag, const std::string& text, size_t count)
{
    std::vector<Pose> poses;
    size_t begin = 0;
    for (;;) {
        const size_t end = text.find(';', begin);
        poses.push_back(parse_pose(count == 1 ? flag : flag + " (pose " + std::to_string(poses.size() + 1) + ")",
                                   text.substr(begin, end == std::string::npos ? std::string::npos : end - begin)));
        if (end == std::string::npos) break;
        begin = end + 1;
    }
    if (poses.size() != count) {
        throw cli::UsageError(flag + ": " + std::to_string(poses.size()) + " pose(s) for " + std::to_string(count) +
                              " car(s); give one X,Y,YAW per car, separated by ';'");
    }
    return poses;
}

std::vector<uint8_t> parse_vehicle_ids(const std::string& flag, const std::string& text)
{
    std::vector<uint8_t> ids;
    for (const auto& item : cli::split_list(flag, text)) {
        const auto id = uint8_t(cli::parse_integer(flag, item, 1, 255));
        if (std::find(ids.begin(), ids.end(), id) != ids.end())
            throw cli::UsageError(flag + ": vehicle " + item + " is listed twice");
        ids.push_back(id);
    }
    return ids;
}

double wrap_angle(double a)
{
    a = std::remainder(a, 2 * M_PI);
    return a <= -M_PI ? a + 2 * M_PI : a;
}

VehicleModel::VehicleModel(const VehicleParameters& parameters, Pose start) : p_(parameters), pose_(start) {}

void VehicleModel::command(double t, MotorMode mode, uint16_t pwm, uint16_t servo_us)
{
    pending_.push_back({t + p_.input_delay, mode, static_cast<uint16_t>(std::min<int>(pwm, 1000)), servo_us});
}

double VehicleModel::steering_for_servo(uint16_t servo_us) const
{
    double unit = std::clamp((double(servo_us) - 1500.0) / 500.0, -1.0, 1.0);
    return unit * p_.max_steering_angle;
}

double VehicleModel::motor_current() const
{
    if (applied_.mode == MotorMode::brake) return p_.idle_current;
    return p_.idle_current + p_.current_per_speed * std::abs(v_);
}

double VehicleModel::battery_voltage() const
{
    // Linear discharge from full to 75 % of full, minus the drop over the internal resistance.
    double used = std::clamp(charge_used_ / p_.battery_capacity, 0.0, 1.0);
    return p_.battery_full * (1.0 - 0.25 * used) - p_.battery_internal_resistance * motor_current();
}

void VehicleModel::stop_at(const Pose& pose, double distance)
{
    pose_ = pose;
    distance_ = distance;
    v_ = accel_ = yaw_rate_ = 0;
}

void VehicleModel::step(double dt)
{
    t_ += dt;
    while (!pending_.empty() && pending_.front().t <= t_) {
        applied_ = pending_.front();
        pending_.pop_front();
    }
    double target_speed = 0, tau = p_.speed_time_constant;
    switch (applied_.mode) {
    case MotorMode::forward: target_speed = p_.max_speed * applied_.pwm / 1000.0; break;
    case MotorMode::reverse: target_speed = -p_.max_speed * applied_.pwm / 1000.0; break;
    case MotorMode::brake: tau = p_.brake_time_constant; break;
    }
    // Exact discretisation of the first-order lags: stable for any dt.
    double v_old = v_;
    v_ = target_speed + (v_ - target_speed) * std::exp(-dt / tau);
    accel_ = (v_ - v_old) / dt;
    double target_delta = steering_for_servo(applied_.servo_us);
    delta_ = target_delta + (delta_ - target_delta) * std::exp(-dt / p_.steering_time_constant);

    double v_mid = 0.5 * (v_ + v_old);
    yaw_rate_ = v_mid * std::tan(delta_) / p_.wheelbase;
    double yaw_mid = pose_.yaw + 0.5 * yaw_rate_ * dt;
    pose_.x += v_mid * std::cos(yaw_mid) * dt;
    pose_.y += v_mid * std::sin(yaw_mid) * dt;
    pose_.yaw = wrap_angle(pose_.yaw + yaw_rate_ * dt);
    distance_ += v_mid * dt;
    charge_used_ += motor_current() * dt;
}

}  // namespace cpm::vehicle
