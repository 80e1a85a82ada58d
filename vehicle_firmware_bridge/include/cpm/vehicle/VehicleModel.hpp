#pragma once
#include <cpm/vehicle/Protocol.hpp>

#include <array>
#include <deque>
#include <string>
#include <vector>

namespace cpm::vehicle {

/// Where an ultrasonic ranger sits on the car (car frame: x forward, y left, from the rear axle).
struct UltrasonicMount
{
    double x = 0, y = 0;
    double yaw = 0;  ///< beam direction, rad
};

/// The simulated car and its microcontroller. Defaults: a 1:10 model car. Every member can be
/// set in a JSON parameter file (see README.md); units are SI.
struct VehicleParameters
{
    double wheelbase = 0.26;              ///< m
    double max_steering_angle = 0.40;     ///< rad, at servo 2000 µs (left) / 1000 µs (right)
    double max_speed = 3.0;               ///< m/s at PWM 1000
    double speed_time_constant = 0.25;    ///< s, first-order response to the PWM
    double brake_time_constant = 0.06;    ///< s, speed decay while braking
    double steering_time_constant = 0.05; ///< s, servo response
    double input_delay = 0.03;            ///< s, from a command to its effect
    double ticks_per_metre = 600;         ///< hall odometer
    double length = 0.40, width = 0.20;   ///< m, body (what other cars' rangers see)
    double rear_overhang = 0.07;          ///< m, from the rear axle to the back of the body
    double battery_full = 8.4;            ///< V
    double battery_capacity = 7200;       ///< A·s (2 Ah)
    double battery_internal_resistance = 0.1;  ///< Ohm
    double idle_current = 0.3;            ///< A
    double current_per_speed = 1.2;       ///< A per m/s
    double imu_yaw_rate_noise = 0.002;    ///< rad/s, standard deviation
    double imu_acceleration_noise = 0.02; ///< m/s^2, standard deviation
    double ultrasonic_min_range = 0.02;   ///< m
    double ultrasonic_max_range = 3.0;    ///< m, reported when nothing echoes
    double ultrasonic_noise = 0.003;      ///< m, standard deviation
    std::array<UltrasonicMount, 3> ultrasonic{{{0.30, 0.0, 0.0}, {0.20, 0.09, 1.5707963267948966},
                                               {0.20, -0.09, -1.5707963267948966}}};  ///< front, left, right
    double watchdog_timeout = 0.25;       ///< s without a valid command → brake
    double physics_rate = 250;            ///< Hz, model integration
    double state_rate = 50;               ///< Hz, state packets
    double observation_noise = 0.0;       ///< m (and rad / 10) standard deviation of VehicleObservation
    double observation_dropout = 0.0;     ///< probability that an observation is not sent

    /// Reads a JSON object of the members above; members not given keep their defaults.
    /// Throws cpm::Error naming the file and member on unknown members or wrong values.
    static VehicleParameters load(const std::string& path);
    static VehicleParameters parse(const std::string& json_text, const std::string& source);
};

/// The pose of a car's rear axle centre in the world, metres and radians.
struct Pose
{
    double x = 0, y = 0, yaw = 0;
};

/// "X,Y,YAW" (metres, radians) from a command-line flag; throws cpm::cli::UsageError naming it.
Pose parse_pose(const std::string& flag, const std::string& text);
/// "X,Y,YAW;X,Y,YAW;…", one pose per car (exactly `count`); throws cpm::cli::UsageError naming
/// the flag, the pose's place in the list and what is wrong.
std::vector<Pose> parse_poses(const std::string& flag, const std::string& text, size_t count);
/// "N" or "N,M,…": distinct vehicle ids in 1..255; throws cpm::cli::UsageError naming the flag.
std::vector<uint8_t> parse_vehicle_ids(const std::string& flag, const std::string& text);

/// Kinematic bicycle model (reference point: rear axle) with first-order speed and steering
/// responses and an input delay. Deterministic; not thread-safe.
class VehicleModel
{
public:
    explicit VehicleModel(const VehicleParameters& parameters, Pose start = {});

    /// The command the microcontroller received at time t (s); it acts after input_delay.
    void command(double t, MotorMode mode, uint16_t pwm, uint16_t servo_us);
    /// Integrates from the model's time to its time + dt (s).
    void step(double dt);

    double time() const { return t_; }
    const Pose& pose() const { return pose_; }
    double speed() const { return v_; }                 ///< m/s, signed
    double steering_angle() const { return delta_; }    ///< rad, positive turns left
    double yaw_rate() const { return yaw_rate_; }       ///< rad/s
    double acceleration() const { return accel_; }      ///< m/s^2 along the car
    double distance() const { return distance_; }       ///< m driven, signed
    double motor_current() const;                       ///< A
    double battery_voltage() const;                     ///< V
    MotorMode motor_mode() const { return applied_.mode; }
    uint16_t motor_pwm() const { return applied_.pwm; }

    /// Puts the car back at `pose` with `distance` driven, standing still: the body hit
    /// something during the last step and stops against it.
    void stop_at(const Pose& pose, double distance);

    /// The steering angle a servo pulse asks for (clamped to max_steering_angle).
    double steering_for_servo(uint16_t servo_us) const;

private:
    struct Input
    {
        double t = 0;
        MotorMode mode = MotorMode::brake;
        uint16_t pwm = 0;
        uint16_t servo_us = 1500;
    };

    VehicleParameters p_;
    Pose pose_;
    double t_ = 0, v_ = 0, delta_ = 0, yaw_rate_ = 0, accel_ = 0, distance_ = 0, charge_used_ = 0;
    std::deque<Input> pending_;
    Input applied_;
};

/// Wraps an angle to (-pi, pi].
double wrap_angle(double a);

}  // namespace cpm::vehicle
