#include <cpm/vehicle/FirmwareSim.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace cpm::vehicle {
namespace {

template <class T>
T saturate(double value)
{
    double lo = std::numeric_limits<T>::min(), hi = std::numeric_limits<T>::max();
    return static_cast<T>(std::lround(std::clamp(value, lo, hi)));
}

}  // namespace

std::string describe_collision(uint8_t vehicle_id, const Collision& c)
{
    char text[200];
    std::snprintf(text, sizeof text, "vehicle %u: hit the wall [%.3f, %.3f, %.3f, %.3f] at x %.3f y %.3f yaw %.3f; stopped against it",
                  unsigned(vehicle_id), c.wall.x1, c.wall.y1, c.wall.x2, c.wall.y2, c.pose.x, c.pose.y, c.pose.yaw);
    return text;
}

FirmwareSim::FirmwareSim(const VehicleParameters& parameters, World world, Pose start, uint8_t vehicle_id,
                         uint32_t seed)
    : p_(parameters), world_(std::move(world)), model_(parameters, start), vehicle_id_(vehicle_id), rng_(seed)
{
}

void FirmwareSim::receive(const uint8_t* data, size_t size)
{
    for (size_t i = 0; i < size; ++i) {
        auto packet = decoder_.push(data[i]);
        if (packet) {
            bad_crc_ = false;
            if (auto* command = std::get_if<CommandPacket>(&*packet)) on_command(*command);
        } else if (data[i] == 0 && decoder_.last_frame_bad()) {
            bad_crc_ = true;
        }
    }
}

void FirmwareSim::on_command(const CommandPacket& command)
{
    if (command.vehicle_id != vehicle_id_) {
        ++stats_.wrong_vehicle;
        wrong_vehicle_ = true;
        return;
    }
    wrong_vehicle_ = false;
    ++stats_.commands;
    answered_ = true;
    last_command_t_ = model_.time();
    command_tick_ = command.tick;
    watchdog_active_ = false;
    motor_command_ = {command.motor_mode, command.motor_pwm};
    model_.command(model_.time(), command.motor_mode, command.motor_pwm, command.servo_us);
}

void FirmwareSim::drive(MotorMode mode, uint16_t pwm, uint16_t servo_us)
{
    driven_ = true;
    motor_command_ = {mode, pwm};
    model_.command(model_.time(), mode, pwm, servo_us);
}

void FirmwareSim::step()
{
    double dt = 1.0 / p_.physics_rate;
    const Pose before = model_.pose();
    const double distance_before = model_.distance();
    model_.step(dt);
    const Segment* wall = world_.wall_hit(body_outline(p_, model_.pose()));
    if (wall != nullptr) {
        model_.stop_at(before, distance_before);
        // A car pushing against the wall creeps up to it and is stopped again and again: one
        // contact lasts until it has been clear of every wall for half a second.
        if (!against_wall()) {
            ++stats_.wall_collisions;
            collisions_.push_back({model_.time(), before, *wall});
        }
        last_contact_t_ = model_.time();
    }
    imu_yaw_ = wrap_angle(imu_yaw_ + (model_.yaw_rate() + noise(p_.imu_yaw_rate_noise)) * dt);
    if (!driven_ && !watchdog_active_ && model_.time() - last_command_t_ > p_.watchdog_timeout) {
        watchdog_active_ = true;
        ++stats_.watchdog_stops;
        motor_command_ = {MotorMode::brake, 0};
        model_.command(model_.time(), MotorMode::brake, 0, 1500);
    }
}

std::vector<Collision> FirmwareSim::take_collisions()
{
    std::vector<Collision> out;
    out.swap(collisions_);
    return out;
}

double FirmwareSim::noise(double sigma)
{
    if (sigma <= 0) return 0;
    return std::normal_distribution<double>(0.0, sigma)(rng_);
}

std::vector<Segment> FirmwareSim::body_outline(const VehicleParameters& p, const Pose& pose)
{
    double c = std::cos(pose.yaw), s = std::sin(pose.yaw);
    double back = -p.rear_overhang, front = p.length - p.rear_overhang, half = p.width / 2;
    auto corner = [&](double x, double y) { return std::pair{pose.x + c * x - s * y, pose.y + s * x + c * y}; };
    std::pair<double, double> k[4] = {corner(back, -half), corner(front, -half), corner(front, half), corner(back, half)};
    std::vector<Segment> out;
    for (int i = 0; i < 4; ++i) {
        auto [ax, ay] = k[i];
        auto [bx, by] = k[(i + 1) % 4];
        out.push_back({ax, ay, bx, by});
    }
    return out;
}

void FirmwareSim::set_other_cars(const std::vector<Pose>& poses)
{
    obstacles_.clear();
    for (const auto& pose : poses) {
        auto outline = body_outline(p_, pose);
        obstacles_.insert(obstacles_.end(), outline.begin(), outline.end());
    }
}

double FirmwareSim::ultrasonic_range(size_t sensor) const
{
    const auto& mount = p_.ultrasonic.at(sensor);
    const Pose& pose = model_.pose();
    double c = std::cos(pose.yaw), s = std::sin(pose.yaw);
    double x = pose.x + c * mount.x - s * mount.y;
    double y = pose.y + s * mount.x + c * mount.y;
    double d = world_.cast_ray(x, y, pose.yaw + mount.yaw, p_.ultrasonic_max_range, obstacles_);
    return std::max(d, p_.ultrasonic_min_range);
}

StatePacket FirmwareSim::make_state_packet()
{
    if (!answered_) ++stats_.unanswered_states;
    answered_ = false;
    ++stats_.state_packets;

    StatePacket packet;
    packet.tick = static_cast<uint32_t>(std::llround(model_.time() * 1000.0));
    packet.vehicle_id = vehicle_id_;
    packet.odometer_steps = saturate<int32_t>(std::floor(model_.distance() * p_.ticks_per_metre));
    packet.speed_mm_s = saturate<int16_t>(model_.speed() * 1000.0);
    packet.imu_yaw_e4 = saturate<int16_t>(imu_yaw_ * 1e4);
    packet.imu_yaw_rate_e3 = saturate<int16_t>((model_.yaw_rate() + noise(p_.imu_yaw_rate_noise)) * 1e3);
    double a_noise = p_.imu_acceleration_noise;
    packet.accel_forward_mm_s2 = saturate<int16_t>((model_.acceleration() + noise(a_noise)) * 1000.0);
    packet.accel_left_mm_s2 = saturate<int16_t>((model_.speed() * model_.yaw_rate() + noise(a_noise)) * 1000.0);
    packet.accel_up_mm_s2 = saturate<int16_t>((9.81 + noise(a_noise)) * 1000.0);
    packet.battery_mv = saturate<uint16_t>(model_.battery_voltage() * 1000.0);
    packet.motor_current_ma = saturate<uint16_t>(model_.motor_current() * 1000.0);
    uint16_t* ranges[3] = {&packet.us_front_mm, &packet.us_left_mm, &packet.us_right_mm};
    for (size_t i = 0; i < 3; ++i) {
        double d = ultrasonic_range(i);
        if (d < p_.ultrasonic_max_range) {
            d = std::clamp(d + noise(p_.ultrasonic_noise), p_.ultrasonic_min_range, p_.ultrasonic_max_range);
        }
        *ranges[i] = saturate<uint16_t>(d * 1000.0);
    }
    packet.status = static_cast<uint8_t>((bad_crc_ ? kStatusBadCrc : 0) | (watchdog_active_ ? kStatusWatchdogStop : 0) |
                                         (wrong_vehicle_ ? kStatusWrongVehicle : 0));
    packet.command_tick = command_tick_;
    return packet;
}

FirmwareStats FirmwareSim::stats() const
{
    FirmwareStats s = stats_;
    s.decoder = decoder_.errors();
    return s;
}

Pose FirmwareSim::observed_pose()
{
    Pose pose = model_.pose();
    pose.x += noise(p_.observation_noise);
    pose.y += noise(p_.observation_noise);
    pose.yaw = wrap_angle(pose.yaw + noise(p_.observation_noise / 10));
    return pose;
}

bool FirmwareSim::drop_observation()
{
    if (p_.observation_dropout <= 0) return false;
    return std::uniform_real_distribution<double>(0, 1)(rng_) < p_.observation_dropout;
}

}  // namespace cpm::vehicle
