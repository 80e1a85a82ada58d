#include "Elements.hpp"

#include <algorithm>
#include <cmath>

namespace cpm::fsm::detail {
namespace {

double clamp1(double v) { return std::clamp(v, -1.0, 1.0); }
double side_range(const Inputs& in, const std::string& side) { return side == "left" ? in.left : in.right; }
double side_sign(const std::string& side) { return side == "left" ? 1.0 : -1.0; }

class Idle : public State
{
public:
    using State::State;
    Output tick(const Inputs&, double) override { return {}; }
};

/// Brakes and stays.
class Stop : public State
{
public:
    using State::State;
    Output tick(const Inputs&, double) override { return {0.0, 0.0, true}; }
};

class Motor : public State
{
public:
    Motor(int id, const Params& p, const Settings& s)
        : State(id, "Motor"), throttle_(p["speed"].get<double>() * s.throttle_per_speed),
          steering_(p["steering"].get<double>()), distance_(p["distance"].get<double>())
    {
    }
    Output tick(const Inputs& in, double) override
    {
        done_ = distance_ > 0 && distance_since_entry(in) >= distance_;
        return {clamp1(throttle_), clamp1(steering_)};
    }
    bool can_finish() const override { return true; }
    bool finished() const override { return done_; }

private:
    double throttle_, steering_, distance_;
    bool done_ = false;
};

/// The wall follower of the original car: y = p e + esum i PID_S + d (e - eold) PID_INVS, with
/// e = measured - clearance on the followed side; y steers towards the wall when too far.
class BasicFollowWall : public State
{
public:
    BasicFollowWall(int id, const std::string& type, const Params& p, const Settings& s)
        : State(id, type), side_(p["side"].get<std::string>()), clearance_(p["clearance"].get<double>()),
          throttle_(p["speed"].get<double>() * s.throttle_per_speed), p_(p["p"].get<double>()),
          i_(p["i"].get<double>()), d_(p["d"].get<double>()), pid_s_(s.tick_period)
    {
    }
    void on_enter(const Inputs& in) override
    {
        State::on_enter(in);
        esum_ = 0;
        eold_.reset();
    }
    Output tick(const Inputs& in, double dt) override { return control(measured(in), dt); }

protected:
    virtual double measured(const Inputs& in) { return side_range(in, side_); }
    /// The original's PID_S is the fixed tick period. Here each tick integrates and
    /// differentiates over the time since the previous measurement (dt, from the samples'
    /// stamps), so that a lost sample (one tick for two periods) or an irregular sensor keeps
    /// the gains per second; at the nominal period it is the original formula exactly. A gap
    /// over 4 periods counts as 4 (input that old brakes the car anyway).
    Output control(double range, double dt)
    {
        const double h = dt > 0 ? std::min(dt, 4 * pid_s_) : pid_s_;
        double e = range - clearance_;
        if (!eold_) eold_ = e;
        esum_ += e * h / pid_s_;
        double y = p_ * e + esum_ * i_ * pid_s_ + d_ * (e - *eold_) / h;
        eold_ = e;
        return {clamp1(throttle_), clamp1(side_sign(side_) * y)};
    }

    std::string side_;
    double clearance_, throttle_, p_, i_, d_, pid_s_;
    double esum_ = 0;
    std::optional<double> eold_;
};

/// BasicFollowWall that ignores range jumps over 2 cm (door frames, niches). The original
/// compared each reading with the last one it took, so a car that drifted more than 2 cm
/// sideways while it ignored a niche never took the wall back behind it and drove blind. Here
/// the 2 cm grow by 10 cm per metre driven since the last reading taken (a heading error
/// of up to 0.1 rad while blind, or a late sample): the wall behind a niche is taken back,
/// the niche itself (deeper than that) is still ignored. While blind, the wall is where the
/// last reading taken put it, moved by the car's own sideways travel since (odometer and the
/// heading turned from that reading's): a steering correction made while blind is seen, so
/// the car holds its line across the niche. (Holding the last reading instead, a car whose last
/// reading before a niche caught the niche's edge, 2 cm deep, steered on those 2 cm all the
/// way across it, turned 0.1 rad, and swerved back behind it.) A reading is taken only when the
/// one before it (taken or not) was within 2 cm of it too: a single reading half in the niche
/// (its edge) is never taken for the wall.
class FollowWall : public BasicFollowWall
{
public:
    FollowWall(int id, const Params& p, const Settings& s) : BasicFollowWall(id, "FollowWall", p, s) {}
    void on_enter(const Inputs& in) override
    {
        BasicFollowWall::on_enter(in);
        expected_ = previous_ = side_range(in, side_);
        taken_odometer_ = odometer_ = in.odometer;
        taken_yaw_ = in.yaw;
    }

protected:
    double measured(const Inputs& in) override
    {
        const double step = std::max(0.0, in.odometer - odometer_);
        odometer_ = in.odometer;
        expected_ -= side_sign(side_) * step * std::sin(std::remainder(in.yaw - taken_yaw_, 2 * M_PI));
        const double r = side_range(in, side_);
        const double blind = std::max(0.0, in.odometer - taken_odometer_);
        const bool steady = std::abs(r - previous_) <= kJump;
        previous_ = r;
        if (steady && std::abs(r - expected_) <= kJump + kDriftPerMetre * blind) {
            expected_ = r;
            taken_odometer_ = in.odometer;
            taken_yaw_ = in.yaw;
        }
        return expected_;
    }

private:
    static constexpr double kJump = 0.02, kDriftPerMetre = 0.1;
    double expected_ = 0, previous_ = 0, taken_odometer_ = 0, taken_yaw_ = 0, odometer_ = 0;
};

/// Clearance changes linearly from the one at entry to target_clearance over `distance`.
class FollowWallRamp : public BasicFollowWall
{
public:
    FollowWallRamp(int id, const Params& p, const Settings& s)
        : BasicFollowWall(id, "FollowWallRamp", p, s), configured_clearance_(p["target_clearance"].get<double>()),
          configured_distance_(p["distance"].get<double>()), target_clearance_(configured_clearance_),
          distance_(configured_distance_)
    {
    }
    void on_enter(const Inputs& in) override
    {
        BasicFollowWall::on_enter(in);
        start_clearance_ = side_range(in, side_);
        done_ = false;
        target_clearance_ = configured_clearance_;  // a target, if any, comes after entry
        distance_ = configured_distance_;
    }
    Output tick(const Inputs& in, double dt) override
    {
        double s = distance_since_entry(in);
        done_ = s >= distance_;
        double f = distance_ > 0 ? std::clamp(s / distance_, 0.0, 1.0) : 1.0;
        clearance_ = start_clearance_ + (target_clearance_ - start_clearance_) * f;
        return control(side_range(in, side_), dt);
    }
    bool can_finish() const override { return true; }
    bool finished() const override { return done_; }
    bool can_take_target() const override { return true; }
    /// The target's lateral offset moves the clearance (towards the left is + y), its forward
    /// offset becomes the ramp's length.
    void set_target(const Target& t) override
    {
        target_clearance_ = start_clearance_ - side_sign(side_) * t.y;
        distance_ = std::max(0.01, t.x);
    }

private:
    double configured_clearance_, configured_distance_, target_clearance_, distance_, start_clearance_ = 0;
    bool done_ = false;
};

std::optional<Target> gate_centre(const Inputs& in, int a, int b, double range);

/// Drives to a point given in the car's frame at entry (dead reckoning from odometer and IMU
/// yaw), steering proportionally to the bearing; finishes within `tolerance`. With a target
/// (a gate: its centre and the direction it faces) the point is `before` m in front of the
/// target, and with `lookahead` > 0 the car follows the line through the target along that
/// direction (pure pursuit, aiming `lookahead` m ahead on the line), so that it arrives facing
/// the gate; it then finishes once it is level with the point and faces along the line (within
/// 0.05 rad; not yet facing it, it follows the line on to 0.3 m before the target). With
/// `track` it re-aims at the gate whenever the camera sees both of its markers again (nearer
/// is more precise). Entered without a target, it drives to its own x, y again.
class ApproachPoint : public State
{
public:
    ApproachPoint(int id, const Params& p, const Settings& s)
        : State(id, "ApproachPoint"), x0_(p["x"].get<double>()), y0_(p["y"].get<double>()), tx_(x0_), ty_(y0_),
          tolerance_(p["tolerance"].get<double>()), throttle_(p["speed"].get<double>() * s.throttle_per_speed),
          gain_(p["steering_gain"].get<double>()), before_(p["before"].get<double>()), lookahead_(p["lookahead"].get<double>()),
          track_(p["track"].get<bool>())
    {
    }
    void on_enter(const Inputs& in) override
    {
        State::on_enter(in);
        x_ = y_ = 0;
        yaw0_ = in.yaw;
        odo_ = in.odometer;
        done_ = false;
        // A target, if any, comes after entry (set_target); until then the state's own point.
        tx_ = x0_;
        ty_ = y0_;
        line_ = false;
        gate_.reset();
    }
    Output tick(const Inputs& in, double) override
    {
        double ds = in.odometer - odo_;
        odo_ = in.odometer;
        double heading = in.yaw - yaw0_;
        x_ += ds * std::cos(heading);
        y_ += ds * std::sin(heading);
        if (track_ && gate_) {
            if (auto seen = gate_centre(in, gate_->marker_a, gate_->marker_b, 1e9)) {
                // The gate as seen now, from the car's frame into the frame at entry.
                const double c = std::cos(heading), s = std::sin(heading);
                Target t = *seen;
                t.x = x_ + c * seen->x - s * seen->y;
                t.y = y_ + s * seen->x + c * seen->y;
                t.yaw = seen->yaw + heading;
                aim_at(t);
            }
        }
        double aim_x = tx_, aim_y = ty_;
        if (line_) {
            // Along the line (dx, dy) through the point: u < 0 before it.
            // Level with the point and facing along the line; or, not yet facing it, on along
            // the line (it leads through the target) until 0.3 m before the target.
            const double u = (x_ - tx_) * dx_ + (y_ - ty_) * dy_;
            const double misalignment = std::abs(std::remainder(heading - std::atan2(dy_, dx_), 2 * M_PI));
            done_ = (u >= -tolerance_ && misalignment <= kAligned) || u >= std::max(-tolerance_, before_ - 0.3);
            aim_x = tx_ + (u + lookahead_) * dx_;
            aim_y = ty_ + (u + lookahead_) * dy_;
        } else {
            done_ = std::hypot(tx_ - x_, ty_ - y_) <= tolerance_;
        }
        if (done_) return {};
        double bearing = std::remainder(std::atan2(aim_y - y_, aim_x - x_) - heading, 2 * M_PI);
        return {clamp1(throttle_), clamp1(gain_ * bearing)};
    }
    bool can_finish() const override { return true; }
    bool finished() const override { return done_; }
    bool can_take_target() const override { return true; }
    void set_target(const Target& t) override
    {
        aim_at(t);
        if (t.marker_a >= 0 || t.marker_b >= 0) gate_ = t;
    }

private:
    void aim_at(const Target& t)
    {
        // t.yaw is the direction the target faces (towards the car); the car drives against it.
        tx_ = t.x + before_ * std::cos(t.yaw);
        ty_ = t.y + before_ * std::sin(t.yaw);
        dx_ = -std::cos(t.yaw);
        dy_ = -std::sin(t.yaw);
        line_ = lookahead_ > 0;
    }

    static constexpr double kAligned = 0.05;  // rad
    double x0_, y0_, tx_, ty_, tolerance_, throttle_, gain_, before_, lookahead_;
    bool track_;
    std::optional<Target> gate_;
    double dx_ = 1, dy_ = 0;
    bool line_ = false;
    double x_ = 0, y_ = 0, yaw0_ = 0, odo_ = 0;
    bool done_ = false;
};

/// The centre of the gate formed by markers a and b (-1: any two markers), if both are seen.
std::optional<Target> gate_centre(const Inputs& in, int a, int b, double range)
{
    const MarkerSighting* first = nullptr;
    const MarkerSighting* second = nullptr;
    for (const auto& m : in.markers) {
        if (m.distance > range) continue;
        bool is_a = a < 0 || m.id == a, is_b = b < 0 || m.id == b;
        if (!first && is_a) first = &m;
        else if (!second && is_b && &m != first) second = &m;
    }
    if (!first || !second) return std::nullopt;
    // The gate faces the car along the normal of the line between its markers (two positions
    // are steadier than either marker's own facing).
    const double cx = (first->x + second->x) / 2, cy = (first->y + second->y) / 2;
    double nx = -(second->y - first->y), ny = second->x - first->x;
    if (nx * -cx + ny * -cy < 0) {
        nx = -nx;
        ny = -ny;
    }
    return Target{cx, cy, std::atan2(ny, nx), a, b};
}

/// Turns (full lock, at `speed`) until the car faces the gate's centre; finishes when aligned,
/// or when it has not seen the gate for `blind` seconds. Until it sees the gate it drives
/// straight on.
class ArucoGateCenter : public State
{
public:
    ArucoGateCenter(int id, const Params& p, const Settings& s)
        : State(id, "ArucoGateCenter"), a_(p["marker_a"].get<int>()), b_(p["marker_b"].get<int>()),
          tolerance_(p["tolerance"].get<double>()), throttle_(p["speed"].get<double>() * s.throttle_per_speed),
          blind_(p["blind"].get<double>())
    {
    }
    void on_enter(const Inputs& in) override
    {
        State::on_enter(in);
        done_ = false;
        seen_ = false;
        last_seen_t_ = in.t;
    }
    Output tick(const Inputs& in, double) override
    {
        if (auto c = gate_centre(in, a_, b_, 1e9)) {
            double bearing = std::atan2(c->y, c->x);
            done_ = std::abs(bearing) <= tolerance_;
            direction_ = bearing >= 0 ? 1.0 : -1.0;
            seen_ = true;
            last_seen_t_ = in.t;
        }
        // Never turning blind: until the gate has been seen, straight on; out of sight for
        // `blind` seconds (too close to see both markers), it is done.
        if (in.t - last_seen_t_ > blind_) done_ = true;
        if (done_ || !seen_) return {clamp1(throttle_), 0.0};
        return {clamp1(throttle_), direction_};
    }
    bool can_finish() const override { return true; }
    bool finished() const override { return done_; }

private:
    int a_, b_;
    double tolerance_, throttle_, blind_, direction_ = 1.0, last_seen_t_ = 0;
    bool done_ = false, seen_ = false;
};

/// A nested machine; finishes when it reaches a state marked "final".
class NestedMachine : public State
{
public:
    NestedMachine(int id, std::unique_ptr<Machine> nested) : State(id, "FSMState"), nested_(std::move(nested)) {}
    void on_enter(const Inputs& in) override
    {
        State::on_enter(in);
        nested_->start(in);
    }
    Output tick(const Inputs& in, double dt) override { return nested_->tick(in, dt); }
    bool can_finish() const override { return true; }
    bool finished() const override { return nested_->in_final_state(); }

private:
    std::unique_ptr<Machine> nested_;
};

// ---- transitions ----

class Always : public Transition
{
public:
    using Transition::Transition;
    bool fires(const Inputs&, const State&) override { return true; }
};

class Distance : public Transition
{
public:
    Distance(int id, int from, int to, const Params& p) : Transition(id, "Distance", from, to), distance_(p["distance"].get<double>()) {}
    bool fires(const Inputs& in, const State& owner) override { return owner.distance_since_entry(in) >= distance_; }

private:
    double distance_;
};

class Finished : public Transition
{
public:
    using Transition::Transition;
    bool fires(const Inputs&, const State& owner) override { return owner.finished(); }
};

class SensorLevel : public Transition
{
public:
    SensorLevel(int id, int from, int to, const Params& p)
        : Transition(id, "SensorLevel", from, to), sensor_(p["sensor"].get<std::string>()),
          above_(p["direction"].get<std::string>() == "above"), level_(p["level"].get<double>()),
          debounce_(p["debounce"].get<int>())
    {
    }
    void reset() override { count_ = 0; }
    bool fires(const Inputs& in, const State&) override
    {
        double r = sensor_ == "front" ? in.front : sensor_ == "left" ? in.left : in.right;
        bool crossed = above_ ? r > level_ : r < level_;
        count_ = crossed ? count_ + 1 : 0;
        return count_ >= debounce_;
    }

private:
    std::string sensor_;
    bool above_;
    double level_;
    int debounce_, count_ = 0;
};

class ArucoGateFound : public Transition
{
public:
    ArucoGateFound(int id, int from, int to, const Params& p)
        : Transition(id, "ArucoGateFound", from, to), a_(p["marker_a"].get<int>()), b_(p["marker_b"].get<int>()),
          range_(p["range"].get<double>())
    {
    }
    bool fires(const Inputs& in, const State&) override
    {
        target_ = gate_centre(in, a_, b_, range_);
        return target_.has_value();
    }
    std::optional<Target> target() const override { return target_; }

private:
    int a_, b_;
    double range_;
    std::optional<Target> target_;
};

class Timeout : public Transition
{
public:
    Timeout(int id, int from, int to, const Params& p) : Transition(id, "Timeout", from, to), seconds_(p["seconds"].get<double>()) {}
    bool fires(const Inputs& in, const State& owner) override { return owner.time_since_entry(in) >= seconds_; }

private:
    double seconds_;
};

const std::vector<ParameterInfo> kWallParams{
    {"side", "side", "right", "wall to follow: left or right"},
    {"clearance", "number", "0.4", "distance to keep to the wall, m", 0.02, 3},
    {"speed", "number", "0.5", "m/s", 0, 3},
    {"p", "number", "4", "steering per m of error", 0, 1000},
    {"i", "number", "0", "steering per m·s of summed error", 0, 1000},
    {"d", "number", "3", "steering per m/s of error change", 0, 1000}};

std::vector<ParameterInfo> with(std::vector<ParameterInfo> base, std::vector<ParameterInfo> more)
{
    base.insert(base.end(), more.begin(), more.end());
    return base;
}

}  // namespace

const std::vector<StateFactory>& state_factories()
{
    static const std::vector<StateFactory> factories{
        {{"Idle", true, false, false, {}}, [](int id, const Params&, const Settings&) { return std::make_unique<Idle>(id, "Idle"); }},
        {{"Stop", true, false, false, {}}, [](int id, const Params&, const Settings&) { return std::make_unique<Stop>(id, "Stop"); }},
        {{"Motor", true, true, false,
          {{"speed", "number", "0.5", "m/s, negative: backwards", -3, 3}, {"steering", "number", "0", "-1..1, + turns left", -1, 1},
           {"distance", "number", "0", "finishes after this many m (0: never)", 0, 1e4}}},
         [](int id, const Params& p, const Settings& s) { return std::make_unique<Motor>(id, p, s); }},
        {{"BasicFollowWall", true, false, false, kWallParams},
         [](int id, const Params& p, const Settings& s) { return std::make_unique<BasicFollowWall>(id, "BasicFollowWall", p, s); }},
        {{"FollowWall", true, false, false, kWallParams},
         [](int id, const Params& p, const Settings& s) { return std::make_unique<FollowWall>(id, p, s); }},
        {{"FollowWallRamp", true, true, true,
          with(kWallParams, {{"target_clearance", "number", "", "clearance at the ramp's end, m", 0.02, 3},
                             {"distance", "number", "", "length of the ramp, m; finishes there", 0.01, 1e4}})},
         [](int id, const Params& p, const Settings& s) { return std::make_unique<FollowWallRamp>(id, p, s); }},
        {{"ApproachPoint", true, true, true,
          {{"x", "number", "0", "point ahead in the car's frame at entry, m", -100, 100},
           {"y", "number", "0", "point to the left, m", -100, 100},
           {"tolerance", "number", "0.1", "finishes within this distance, m", 0.001, 10}, {"speed", "number", "0.4", "m/s", 0, 3},
           {"steering_gain", "number", "2", "steering per rad of bearing", 0, 100},
           {"before", "number", "0", "with a target: the point this far in front of it (along the way it faces), m", -10, 10},
           {"lookahead", "number", "0", "with a target: > 0 follows the line through it, aiming this far ahead, m", 0, 10},
           {"track", "bool", "true", "with a gate as target: re-aim whenever both its markers are seen"}}},
         [](int id, const Params& p, const Settings& s) { return std::make_unique<ApproachPoint>(id, p, s); }},
        {{"ArucoGateCenter", true, true, false,
          {{"marker_a", "integer", "-1", "marker id (-1: any)", -1, 999}, {"marker_b", "integer", "-1", "marker id (-1: any)", -1, 999},
           {"tolerance", "number", "0.05", "aligned within this bearing, rad", 0.001, 3.15}, {"speed", "number", "0.3", "m/s", 0, 3},
           {"blind", "number", "0.3", "finishes after this long without seeing the gate, s", 0, 60}}},
         [](int id, const Params& p, const Settings& s) { return std::make_unique<ArucoGateCenter>(id, p, s); }},
        {{"FSMState", true, true, false,
          {{"machine", "machine", "", "a nested machine: an object like this file's, or \"file\": a path"},
           {"file", "file", "", "a JSON file with the nested machine, relative to this one"}}},
         nullptr},
    };
    return factories;
}

const std::vector<TransitionFactory>& transition_factories()
{
    static const std::vector<TransitionFactory> factories{
        {{"Always", false, false, false, {}},
         [](int id, int from, int to, const Params&) { return std::make_unique<Always>(id, "Always", from, to); }},
        {{"Distance", false, false, false, {{"distance", "number", "", "m driven since the owner was entered", 0, 1e4}}},
         [](int id, int from, int to, const Params& p) { return std::make_unique<Distance>(id, from, to, p); }},
        {{"Finished", false, false, false, {}},
         [](int id, int from, int to, const Params&) { return std::make_unique<Finished>(id, "Finished", from, to); }},
        {{"SensorLevel", false, false, false,
          {{"sensor", "sensor", "", "front, left or right"}, {"level", "number", "", "threshold, m", 0, 10},
           {"direction", "direction", "above", "above or below the level"},
           {"debounce", "integer", "1", "consecutive ticks the condition must hold", 1, 10000}}},
         [](int id, int from, int to, const Params& p) { return std::make_unique<SensorLevel>(id, from, to, p); }},
        {{"ArucoGateFound", false, false, false,
          {{"marker_a", "integer", "-1", "marker id (-1: any)", -1, 999}, {"marker_b", "integer", "-1", "marker id (-1: any)", -1, 999},
           {"range", "number", "2.0", "both markers nearer than this, m", 0.01, 20}}},
         [](int id, int from, int to, const Params& p) { return std::make_unique<ArucoGateFound>(id, from, to, p); }},
        {{"Timeout", false, false, false, {{"seconds", "number", "", "time in the owner, s", 0, 86400}}},
         [](int id, int from, int to, const Params& p) { return std::make_unique<Timeout>(id, from, to, p); }},
    };
    return factories;
}

std::unique_ptr<State> make_nested_state(int id, std::unique_ptr<Machine> nested)
{
    return std::make_unique<NestedMachine>(id, std::move(nested));
}

}  // namespace cpm::fsm::detail
