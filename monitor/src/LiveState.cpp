#include <cpm/monitor/LiveState.hpp>

#include <cpm/topics.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

namespace cpm::monitor {
namespace {

const char* level_name(unsigned level)
{
    switch (level) {
    case 1: return "error";
    case 2: return "warn";
    case 3: return "info";
    default: return "debug";
    }
}

/// JSON has no NaN or infinity: a value that is not finite becomes null.
nlohmann::json number(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }

double seconds(uint64_t later_ns, uint64_t earlier_ns) { return later_ns > earlier_ns ? double(later_ns - earlier_ns) * 1e-9 : 0.0; }

}  // namespace

LiveState::LiveState(std::optional<vehicle::World> world, LiveOptions options) : world_(std::move(world)), options_(options) {}

LiveState::Car& LiveState::car(uint8_t id) { return cars_[id]; }

void LiveState::on_state(const VehicleState& s, uint64_t now_ns)
{
    std::lock_guard lock(mutex_);
    Car& c = car(s.vehicle_id());
    c.state = s;
    c.state_at_ns = now_ns;
    add_plot_point(c, now_ns);
    ++version_;
}

void LiveState::on_observation(const VehicleObservation& o, uint64_t now_ns)
{
    std::lock_guard lock(mutex_);
    Car& c = car(o.vehicle_id());
    c.observed = o.pose();
    c.observed_at_ns = now_ns;
    c.observed_stamp_ns = o.header().create_stamp().nanoseconds();
    ++version_;
}

void LiveState::on_ranges(const RangeSensors& r, uint64_t)
{
    std::lock_guard lock(mutex_);
    car(r.vehicle_id()).ranges = r;
    ++version_;
}

void LiveState::on_fsm(const FsmStatus& f, uint64_t)
{
    std::lock_guard lock(mutex_);
    car(f.vehicle_id()).fsm = f;
    ++version_;
}

void LiveState::on_markers(const ArucoMarkers& m, uint64_t now_ns)
{
    std::lock_guard lock(mutex_);
    Car& c = car(m.vehicle_id());
    c.markers = m;
    c.markers_at_ns = now_ns;
    ++version_;
}

void LiveState::on_log(const Log& l, uint64_t)
{
    std::lock_guard lock(mutex_);
    log_.push_back({{"t_ns", l.stamp().nanoseconds()}, {"id", l.id()}, {"level", level_name(l.log_level())}, {"text", l.content()}});
    while (log_.size() > options_.log_lines) log_.pop_front();
    ++version_;
}

void LiveState::on_history_status(const HistoryStatus& h, uint64_t now_ns)
{
    std::lock_guard lock(mutex_);
    for (const auto& t : h.topics()) {
        Topic& topic = topics_[t.topic()];
        topic.history_rate_hz = t.rate_hz();
        topic.history_seen_ns = now_ns;
    }
    ++version_;
}

std::vector<uint8_t> LiveState::car_ids() const
{
    std::lock_guard lock(mutex_);
    std::vector<uint8_t> ids;
    for (const auto& [id, c] : cars_) ids.push_back(id);
    return ids;
}

void LiveState::count(const std::string& topic, size_t n, uint64_t now_ns)
{
    std::lock_guard lock(mutex_);
    auto& arrivals = topics_[topic].arrivals;
    arrivals.insert(arrivals.end(), n, now_ns);
    const uint64_t window = uint64_t(options_.rate_window_s * 1e9);
    while (!arrivals.empty() && arrivals.front() + window < now_ns) arrivals.pop_front();
}

void LiveState::set_observation_writers(std::vector<std::string> names)
{
    std::sort(names.begin(), names.end());
    names.erase(std::unique(names.begin(), names.end()), names.end());
    std::lock_guard lock(mutex_);
    if (observation_writers_ == names) return;
    observation_writers_ = std::move(names);
    ++version_;
}

void LiveState::set_source(const std::string& source)
{
    std::lock_guard lock(mutex_);
    if (source_ != source) ++version_;
    source_ = source;
}

uint64_t LiveState::version() const
{
    std::lock_guard lock(mutex_);
    return version_;
}

namespace {

struct Placed
{
    Pose2D pose;
    const char* from;    ///< the topic the pose came from
    uint64_t stamp_ns;   ///< its sample's create_stamp
};

/// Where a car is drawn: seen from outside when that is fresh, else where it thinks it is.
template <class Car>
std::optional<Placed> pose_of(const Car& c, uint64_t now_ns, double stale_after_s)
{
    if (c.observed && (seconds(now_ns, c.observed_at_ns) <= stale_after_s || !c.state)) {
        return Placed{*c.observed, topics::vehicle_observation.name, c.observed_stamp_ns};
    }
    if (c.state) return Placed{c.state->pose(), topics::vehicle_state.name, c.state->header().create_stamp().nanoseconds()};
    return std::nullopt;
}

/// In words, who placed a car: its own estimate, or the writers of vehicleObservation that
/// discovery shows (the positioning system, a simulator's ground truth).
std::string pose_source(const std::string& from, const std::vector<std::string>& writers)
{
    if (from != topics::vehicle_observation.name) return "its own estimate (vehicleState)";
    const bool ips = std::find(writers.begin(), writers.end(), "ips_node") != writers.end();
    const bool simulator = std::any_of(writers.begin(), writers.end(), [](const std::string& w) {
        return w.rfind("firmware_sim", 0) == 0 || w.rfind("firmware_hil", 0) == 0;
    });
    if (ips && !simulator) return "the positioning system (ips_node)";
    if (simulator && !ips) return "the simulator's ground truth";
    std::string names;
    for (const auto& w : writers) names += (names.empty() ? "" : ", ") + w;
    return names.empty() ? "vehicleObservation" : "vehicleObservation from " + names;
}

}  // namespace

double LiveState::clearance(const Car& c, std::string* to) const
{
    const uint64_t now_ns = std::max(c.state_at_ns, c.observed_at_ns);
    const auto p = pose_of(c, now_ns, options_.stale_after_s);
    double best = std::numeric_limits<double>::infinity();
    if (!p) return best;
    if (world_) {
        best = world_->nearest_wall(p->pose.x(), p->pose.y());
        if (to) *to = "wall";
    }
    for (const auto& [id, other] : cars_) {
        if (&other == &c) continue;
        const auto q = pose_of(other, now_ns, options_.stale_after_s);
        const uint64_t other_at = std::max(other.state_at_ns, other.observed_at_ns);
        if (!q || seconds(now_ns, other_at) > options_.stale_after_s) continue;
        const double d = std::hypot(q->pose.x() - p->pose.x(), q->pose.y() - p->pose.y());
        if (d < best) {
            best = d;
            if (to) *to = "car " + std::to_string(id);
        }
    }
    return best;
}

void LiveState::add_plot_point(Car& c, uint64_t now_ns)
{
    if (!c.plot.empty() && seconds(now_ns, c.plot.back().at_ns) < options_.plot_period_s) return;
    c.plot.push_back({now_ns, c.state ? c.state->speed() : 0.0, clearance(c, nullptr)});
    const uint64_t window = uint64_t(options_.plot_window_s * 1e9);
    while (!c.plot.empty() && c.plot.front().at_ns + window < now_ns) c.plot.pop_front();
}

nlohmann::json LiveState::snapshot(uint64_t now_ns) const
{
    std::lock_guard lock(mutex_);
    nlohmann::json vehicles = nlohmann::json::array();
    for (const auto& [id, c] : cars_) {
        const auto placed = pose_of(c, now_ns, options_.stale_after_s);
        if (!placed) continue;
        const Pose2D& pose = placed->pose;  // a car known only by its ranges or its FSM: nowhere to draw it
        const uint64_t newest = std::max(c.state_at_ns, c.observed_at_ns);
        const double age_s = seconds(now_ns, newest);
        nlohmann::json v{{"id", id},
                         {"x", number(pose.x())},
                         {"y", number(pose.y())},
                         {"yaw", number(pose.yaw())},
                         {"pose_from", placed->from},
                         {"pose_source", pose_source(placed->from, observation_writers_)},
                         {"pose_stamp_ns", placed->stamp_ns},
                         {"age_ms", age_s * 1e3},
                         {"stale", age_s > options_.stale_after_s}};
        if (c.state) {
            const auto& s = *c.state;
            v["speed"] = number(s.speed());
            v["steering"] = number(s.steering_servo());
            v["throttle"] = number(s.motor_throttle());
            v["battery_voltage"] = number(s.battery_voltage());
            v["odometer_m"] = number(s.odometer_distance());
            v["state_stamp_ns"] = s.header().create_stamp().nanoseconds();
            v["state_age_ms"] = seconds(now_ns, c.state_at_ns) * 1e3;
        } else {
            v["speed"] = nullptr;
        }
        if (c.ranges) v["ranges"] = {{"front", number(c.ranges->front())}, {"left", number(c.ranges->left())}, {"right", number(c.ranges->right())}};
        if (c.fsm) {
            v["fsm_state"] = c.fsm->state_type();
            v["fsm_state_id"] = c.fsm->state_id();
            v["fsm_entered_ns"] = c.fsm->entered_ns();
            // The FSM's entry time is on the lab's clock, as are the car's stamps (real, simulated
            // or replayed): how long it has been in its state is read on that clock.
            if (c.state) v["fsm_for_s"] = seconds(c.state->header().create_stamp().nanoseconds(), c.fsm->entered_ns());
        } else {
            v["fsm_state"] = nullptr;
        }
        std::string to;
        const double d = clearance(c, &to);
        v["clearance_m"] = number(d);
        if (std::isfinite(d)) v["clearance_to"] = to;
        nlohmann::json seen = nlohmann::json::array();
        if (c.markers && seconds(now_ns, c.markers_at_ns) <= options_.markers_for_s) {
            for (const auto& m : c.markers->markers()) {
                seen.push_back({{"id", m.id()}, {"distance", number(m.distance())}, {"x", number(m.pose().x())}, {"y", number(m.pose().y())}});
            }
        }
        v["markers"] = std::move(seen);
        vehicles.push_back(std::move(v));
    }
    nlohmann::json topics = nlohmann::json::array();
    const uint64_t window = uint64_t(options_.rate_window_s * 1e9);
    for (const auto& [name, t] : topics_) {
        size_t recent = 0;
        for (auto a : t.arrivals) recent += a + window >= now_ns;
        if (!t.arrivals.empty() || !t.history_rate_hz) {
            topics.push_back({{"name", name}, {"rate_hz", double(recent) / options_.rate_window_s}, {"from", "monitor"}});
        } else if (seconds(now_ns, t.history_seen_ns) < 5.0) {
            topics.push_back({{"name", name}, {"rate_hz", number(*t.history_rate_hz)}, {"from", "history"}});
        }
    }
    return {{"t_ns", now_ns},
            {"source", source_},
            {"vehicles", std::move(vehicles)},
            {"topics", std::move(topics)},
            {"log", nlohmann::json(std::vector<nlohmann::json>(log_.begin(), log_.end()))}};
}

nlohmann::json LiveState::plots(uint64_t now_ns) const
{
    std::lock_guard lock(mutex_);
    nlohmann::json out = nlohmann::json::array();
    for (const auto& [id, c] : cars_) {
        nlohmann::json points = nlohmann::json::array();
        for (const auto& p : c.plot) points.push_back({-seconds(now_ns, p.at_ns), number(p.speed), number(p.clearance)});
        out.push_back({{"id", id}, {"points", std::move(points)}});
    }
    return {{"t_ns", now_ns}, {"window_s", options_.plot_window_s}, {"vehicles", std::move(out)}};
}

}  // namespace cpm::monitor
