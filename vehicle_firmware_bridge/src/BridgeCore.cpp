#include <cpm/vehicle/BridgeCore.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace cpm::vehicle {

namespace {

/// A command's field: its name is spelled out ("trajectory_points[3].vx") only when it is at
/// fault. Every cycle of every car checks the newest commands, a trajectory's 80 points and
/// more among them, and building their names cost the bridge's loop 400 strings a cycle.
struct Field
{
    const char* member;
    const char* array = nullptr;  ///< the member is in array[index]
    size_t index = 0;

    std::string name() const { return array ? std::string(array) + "[" + std::to_string(index) + "]." + member : std::string(member); }
};

/// Finds the first field of a command that is not finite or not within its range.
class FieldCheck
{
public:
    void finite(const Field& field, double value)
    {
        if (problem.empty() && !std::isfinite(value)) problem = field.name() + " = " + text(value) + " is not a finite number";
    }
    void within(const Field& field, double value, double lo, double hi)
    {
        finite(field, value);
        if (problem.empty() && (value < lo || value > hi))
            problem = field.name() + " = " + text(value) + " is outside [" + text(lo) + ", " + text(hi) + "]";
    }
    std::string problem;

private:
    static std::string text(double v)
    {
        char buffer[32];
        std::snprintf(buffer, sizeof buffer, "%g", v);
        return buffer;
    }
};

}  // namespace

std::string command_problem(const VehicleCommandDirect& command, const Calibration&)
{
    FieldCheck check;
    check.within({"motor_throttle"}, command.motor_throttle(), -1, 1);
    check.within({"steering_servo"}, command.steering_servo(), -1, 1);
    return check.problem;
}

std::string command_problem(const VehicleCommandSpeedCurvature& command, const Calibration& c)
{
    FieldCheck check;
    check.within({"speed"}, command.speed(), -c.max_speed, c.max_speed);
    check.finite({"curvature"}, command.curvature());
    return check.problem;
}

std::string command_problem(const VehicleCommandTrajectory& command, const Calibration& c)
{
    FieldCheck check;
    const auto& points = command.trajectory_points();
    for (size_t i = 0; i < points.size() && check.problem.empty(); ++i) {
        check.finite({"px", "trajectory_points", i}, points[i].px());
        check.finite({"py", "trajectory_points", i}, points[i].py());
        check.within({"vx", "trajectory_points", i}, points[i].vx(), -c.max_speed, c.max_speed);
        check.within({"vy", "trajectory_points", i}, points[i].vy(), -c.max_speed, c.max_speed);
    }
    return check.problem;
}

std::string command_problem(const VehicleCommandPathTracking& command, const Calibration& c)
{
    FieldCheck check;
    check.within({"speed"}, command.speed(), -c.max_speed, c.max_speed);
    const auto& path = command.path();
    for (size_t i = 0; i < path.size() && check.problem.empty(); ++i) {
        check.finite({"pose.x", "path", i}, path[i].pose().x());
        check.finite({"pose.y", "path", i}, path[i].pose().y());
        check.finite({"pose.yaw", "path", i}, path[i].pose().yaw());
        check.finite({"s", "path", i}, path[i].s());
    }
    return check.problem;
}

const char* to_string(Anomaly anomaly)
{
    switch (anomaly) {
    case Anomaly::refused_command: return "refused_commands";
    case Anomaly::controller_restart: return "controller_restarts";
    case Anomaly::odometer_jump: return "odometer_jumps";
    case Anomaly::battery_out_of_range: return "battery_out_of_range";
    case Anomaly::line_lag: return "line_lags";
    }
    return "?";
}

const char* to_string(ActiveCommand command)
{
    switch (command) {
    case ActiveCommand::none: return "none";
    case ActiveCommand::stopped: return "stop_request";
    case ActiveCommand::direct: return "direct";
    case ActiveCommand::speed_curvature: return "speed_curvature";
    case ActiveCommand::trajectory: return "trajectory";
    case ActiveCommand::path_tracking: return "path_tracking";
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

void BridgeCore::notice(std::vector<Notice>& notices, Anomaly kind, std::string message)
{
    ++anomaly_counts_[size_t(kind)];
    notices.push_back({kind, std::move(message)});
}

void BridgeCore::dead_reckon(const StatePacket& packet, uint64_t t_ns, double tick_dt, std::vector<Notice>& notices)
{
    double imu_yaw = packet.imu_yaw_e4 * 1e-4;
    // No car drives further than twice its top speed allows in the time between two packets
    // (at least one 50 Hz period, plus a centimetre for the odometer's resolution).
    const double ds = last_steps_ ? (double(packet.odometer_steps) - double(*last_steps_)) / c_.ticks_per_metre : 0.0;
    const double ds_max = 2 * c_.max_speed * std::max(tick_dt, 0.02) + 0.01;
    if (last_steps_ && std::abs(ds) > ds_max) {
        char message[160];
        std::snprintf(message, sizeof message,
                      "odometer jumped by %.2f m in %.0f ms (at most %.2f m is possible): step ignored, odometer rebased",
                      ds, tick_dt * 1e3, ds_max);
        notice(notices, Anomaly::odometer_jump, message);
        last_steps_.reset();
    }
    if (!last_steps_) {
        // New link, restarted controller or implausible step: keep the pose, rebase odometer
        // and IMU heading on this packet.
        yaw_offset_ = wrap_angle(pose_.yaw - imu_yaw);
    } else {
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
    if (std::abs(request.speed) < 1e-3 && std::abs(speed) < 0.05) {
        speed_controller_.reset();
        return a;  // brake: nothing to drive to
    }
    if (line_lagging_) {
        // Feedback through a backed-up line would act on the past: feed-forward only.
        speed_controller_.reset();
        speed = request.speed;
    }
    a.throttle = speed_controller_.update(request.speed, speed, dt);
    a.brake = false;
    return a;
}

template <class T>
bool BridgeCore::obeyable(const SampleResult<T>& command, ActiveCommand kind, const CommandInputs& in,
                          std::vector<Notice>& notices)
{
    const uint64_t created = command.sample.header().create_stamp().nanoseconds();
    if (!command.valid || !fresh(command.age_ns, created, in)) return false;
    std::string problem = command_problem(command.sample, c_);
    if (problem.empty()) return true;
    // The same sample stays the newest until another arrives: report it once.
    if (refused_stamp_[size_t(kind)] != created) {
        refused_stamp_[size_t(kind)] = created;
        notice(notices, Anomaly::refused_command,
               std::string("refused a ") + to_string(kind) + " command created at " + std::to_string(created) + ": " +
                   problem);
    }
    return false;
}

BridgeCore::Actuation BridgeCore::choose(const CommandInputs& in, uint64_t t_ns, double speed, double dt,
                                         ActiveCommand& active, std::vector<Notice>& notices)
{
    if (obeyable(in.direct, ActiveCommand::direct, in, notices)) {
        active = ActiveCommand::direct;
        Actuation a;
        a.throttle = in.direct.sample.motor_throttle();
        a.steering = in.direct.sample.steering_servo();
        a.brake = false;
        return a;
    }
    if (obeyable(in.speed_curvature, ActiveCommand::speed_curvature, in, notices)) {
        active = ActiveCommand::speed_curvature;
        return drive({in.speed_curvature.sample.speed(), in.speed_curvature.sample.curvature()}, speed, dt);
    }
    if (obeyable(in.trajectory, ActiveCommand::trajectory, in, notices)) {
        active = ActiveCommand::trajectory;
        uint64_t t_ref = t_ns + static_cast<uint64_t>(c_.lookahead_time * 1e9);
        if (auto reference = interpolate_trajectory(in.trajectory.sample.trajectory_points(), t_ref)) {
            return drive(track_trajectory(c_, *reference, pose_), speed, dt);
        }
        return drive({}, speed, dt);  // the trajectory does not cover now: stop
    }
    if (obeyable(in.path_tracking, ActiveCommand::path_tracking, in, notices)) {
        active = ActiveCommand::path_tracking;
        const auto& command = in.path_tracking.sample;
        if (auto request = track_path(c_, command.path(), command.speed(), pose_, speed)) {
            return drive(*request, speed, dt);
        }
        return drive({}, speed, dt);
    }
    active = in.stop_request_ns ? ActiveCommand::stopped : ActiveCommand::none;
    speed_controller_.reset();
    return {};
}

double BridgeCore::plausible_battery(uint16_t battery_mv, std::vector<Notice>& notices)
{
    const double v = battery_mv * 1e-3;
    if (v >= c_.battery_min_voltage && v <= c_.battery_max_voltage) return battery_v_ = v;
    char message[160];
    std::snprintf(message, sizeof message,
                  "battery reads %.3f V, outside [%g, %g] V (a sensor fault): publishing the last plausible reading "
                  "(%.3f V) instead",
                  v, c_.battery_min_voltage, c_.battery_max_voltage, battery_v_);
    notice(notices, Anomaly::battery_out_of_range, message);
    return battery_v_;
}

void BridgeCore::watch_line_lag(const StatePacket& packet, std::vector<Notice>& notices)
{
    // The controller echoes the tick of the last command it applied (the state it answered); at
    // 50 Hz that command is one or two behind the newest sent. Ten (200 ms) behind, the line
    // holds a backlog; the spell lasts until the echo is about back in step (four behind at
    // most: a slower line may run three behind): feedback through a line still catching up
    // (180, 100 ms late) overshoots. An echo older than every command kept is far behind; a
    // controller that has applied none yet (0), or one we never sent, says nothing.
    constexpr uint32_t kLagLimit = 10, kInStep = 4;
    std::optional<uint32_t> behind;
    if (packet.command_tick != 0 && !answered_.empty()) {
        const auto echoed = std::find(answered_.rbegin(), answered_.rend(), packet.command_tick);
        if (echoed != answered_.rend()) behind = uint32_t(echoed - answered_.rbegin());
        else if (int32_t(packet.command_tick - answered_.front()) < 0) behind = uint32_t(answered_.size());
    }
    const bool lagging = behind && *behind > (line_lagging_ ? kInStep : kLagLimit);
    if (lagging && !line_lagging_) {
        notice(notices, Anomaly::line_lag,
               "the controller applies commands " + std::to_string(*behind) +
                   " behind the newest sent (a backed-up line; the AVR firmware ignores those answering a state over " +
                   std::to_string(kCommandMaxAgeMs) + " ms old): speed feedback paused until it catches up");
    }
    line_lagging_ = lagging;
}

CommandPacket BridgeCore::to_packet(const Actuation& a, uint32_t answering)
{
    // Enough to tell an echo kLagLimit behind from one in step, and a second's worth more.
    constexpr size_t kAnsweredKept = 64;
    CommandPacket packet;
    packet.tick = answering;
    answered_.push_back(answering);
    if (answered_.size() > kAnsweredKept) answered_.pop_front();
    packet.vehicle_id = vehicle_id_;
    if (a.brake || !std::isfinite(a.throttle) || !std::isfinite(a.steering)) {
        packet.motor_mode = MotorMode::brake;
    } else {
        packet.motor_mode = a.throttle >= 0 ? MotorMode::forward : MotorMode::reverse;
        packet.motor_pwm = static_cast<uint16_t>(std::lround(std::min(std::abs(a.throttle), 1.0) * 1000));
    }
    double servo = c_.servo_centre_us + (std::isfinite(a.steering) ? a.steering : 0.0) * c_.servo_range_us;
    packet.servo_us = static_cast<uint16_t>(std::lround(std::clamp(servo, 0.0, 65535.0)));
    return packet;
}

double BridgeCore::take_in(const StatePacket& packet, uint64_t t_ns, BridgeCycle& out)
{
    // Ticks are unsigned 32-bit ms: a small step back is a restart, a large one a wrap.
    const uint32_t tick_step = last_tick_ ? packet.tick - *last_tick_ : 20;
    const bool restarted = tick_step > 0x80000000u;
    const double tick_dt = restarted ? 0.02 : tick_step * 1e-3;
    if (restarted) {
        notice(out.notices, Anomaly::controller_restart,
               "the controller restarted (tick " + std::to_string(*last_tick_) + " -> " + std::to_string(packet.tick) +
                   "): odometer and heading rebased, pose kept");
        last_steps_.reset();
        answered_.clear();  // ticks of its previous life
    }
    out.measured_ns = measured_time(packet.tick, t_ns);
    last_tick_ = packet.tick;
    dead_reckon(packet, t_ns, tick_dt, out.notices);
    return tick_dt;
}

BridgeCycle BridgeCore::on_waiting_state_packet(const StatePacket& packet, uint64_t t_ns)
{
    BridgeCycle out;
    (void)take_in(packet, t_ns, out);
    fill_outputs(packet, packet.speed_mm_s * 1e-3, last_actuation_, out);
    return out;
}

BridgeCycle BridgeCore::on_state_packet(const StatePacket& packet, uint64_t t_ns, const CommandInputs& commands)
{
    BridgeCycle out;
    const double dt = std::clamp(take_in(packet, t_ns, out), 1e-3, 0.1);
    double speed = packet.speed_mm_s * 1e-3;
    // While the controller says its watchdog holds the brake, our commands do not reach the
    // motor (a flooded or broken line): integrating the speed error then would send the car off
    // too fast once they do.
    if (packet.status & kStatusWatchdogStop) speed_controller_.reset();
    watch_line_lag(packet, out.notices);
    out.discard_queued_output = line_lagging_;

    Actuation a = choose(commands, t_ns, speed, dt, out.active, out.notices);
    if (out.active != last_active_) speed_controller_.reset();
    last_active_ = out.active;
    out.command = to_packet(a, packet.tick);
    last_actuation_ = a;
    fill_outputs(packet, speed, a, out);
    return out;
}

void BridgeCore::fill_outputs(const StatePacket& packet, double speed, const Actuation& a, BridgeCycle& out)
{
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
    s.battery_voltage(plausible_battery(packet.battery_mv, out.notices));
    s.motor_current(packet.motor_current_ma * 1e-3);
    s.motor_throttle(a.brake ? 0.0 : a.throttle);
    s.steering_servo(a.steering);

    RangeSensors& r = out.ranges;
    r.vehicle_id(vehicle_id_);
    r.front(packet.us_front_mm * 1e-3);
    r.left(packet.us_left_mm * 1e-3);
    r.right(packet.us_right_mm * 1e-3);
    r.hall_distance(distance_);
}

}  // namespace cpm::vehicle
