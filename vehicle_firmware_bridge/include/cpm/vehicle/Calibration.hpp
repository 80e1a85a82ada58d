#pragma once
#include <string>

namespace cpm::vehicle {

/// How vehicle_bridge turns the microcontroller's units into the lab's and back, and the
/// gains of its on-board controllers. Defaults match firmware_sim's defaults; every member
/// can be set in a JSON file (`--calibration`, see README.md). Units are SI.
struct Calibration
{
    double ticks_per_metre = 600;       ///< hall odometer
    double servo_centre_us = 1500;      ///< servo pulse for steering_servo = 0
    double servo_range_us = 500;        ///< pulse change for steering_servo = ±1 (+ turns left)
    double max_steering_angle = 0.40;   ///< rad at steering_servo = 1
    double wheelbase = 0.26;            ///< m
    double throttle_per_speed = 1 / 3.0;///< feed-forward: throttle per m/s
    double speed_kp = 0.4;              ///< throttle per m/s of speed error
    double speed_ki = 1.0;              ///< throttle per m of integrated speed error
    double speed_integral_limit = 0.3;  ///< bound on the integral term (throttle)
    double trajectory_kx = 2.0;         ///< 1/s, along-track gain (Kanayama)
    double trajectory_ky = 16.0;        ///< 1/m^2, cross-track gain
    double trajectory_ktheta = 6.0;     ///< 1/m, heading gain
    double lookahead_time = 0.05;       ///< s, the actuation delay the trajectory reference leads by
    double path_lookahead_min = 0.3;    ///< m, pure pursuit lookahead at low speed
    double path_lookahead_per_speed = 0.4; ///< s, lookahead grows with speed
    double path_stop_deceleration = 1.0;///< m/s^2, how the car slows for the end of a path
    double command_timeout = 1.0;       ///< s, a command older than this is not fresh
    double publish_delay = 0.001;       ///< s, expected DDS delivery added to valid_after_stamp
    double max_speed = 3.0;             ///< m/s; a command asking for more is refused, and an
                                        ///< odometer step faster than twice this is implausible
    double battery_min_voltage = 3.0;   ///< V; a reading outside [min, max] is a sensor fault
    double battery_max_voltage = 20.0;  ///< V

    /// Reads a JSON object of the members above; members not given keep their defaults.
    /// Throws cpm::Error naming the file and member on unknown members or wrong values.
    static Calibration load(const std::string& path);
    static Calibration parse(const std::string& json_text, const std::string& source);
};

}  // namespace cpm::vehicle
