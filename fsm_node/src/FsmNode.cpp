#include <cpm/fsm/FsmNode.hpp>

#include <cpm/AsyncReader.hpp>
#include <cpm/Logging.hpp>
#include <cpm/Reader.hpp>
#include <cpm/Timer.hpp>
#include <cpm/timer_ids.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/init.hpp>
#include <cpm/percentile.hpp>
#include <cpm/stamp_message.hpp>
#include <cpm/topics.hpp>

#include <FsmStatus.h>
#include <StopRequest.h>
#include <VehicleCommandDirect.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <deque>
#include <mutex>
#include <thread>

namespace cpm::fsm {

Inputs inputs_from(const VehicleState& state, const RangeSensors& ranges, const ArucoMarkers* markers, double t_s)
{
    Inputs in;
    in.t = t_s;
    in.odometer = state.odometer_distance();
    in.yaw = state.pose().yaw();
    in.speed = state.speed();
    in.front = ranges.front();
    in.left = ranges.left();
    in.right = ranges.right();
    if (markers) {
        for (const auto& m : markers->markers()) in.markers.push_back({m.id(), m.pose().x(), m.pose().y(), m.pose().yaw(), m.distance()});
    }
    return in;
}

void RunReport::add(const Inputs& in, int state)
{
    if (!started_) {
        start_odometer_ = in.odometer;
        start_yaw_ = in.yaw;
        started_ = true;
    }
    odometer_ = in.odometer;
    yaw_ = in.yaw;
    ranges_[state].push_back({in.left, in.right});
}

std::string RunReport::text() const
{
    char line[512];
    const double turned = std::remainder(yaw_ - start_yaw_, 2 * M_PI) * 180 / M_PI;
    std::snprintf(line, sizeof line, "report: driven %.2f m, heading changed by %.0f deg\n", odometer_ - start_odometer_, turned);
    std::string out = line;
    for (const auto& [state, samples] : ranges_) {
        auto wall = walls_.find(state);
        if (wall == walls_.end() || samples.empty()) continue;
        double sum = 0;
        std::vector<double> deviation;
        for (const auto& [left, right] : samples) {
            const double r = wall->second.first == "left" ? left : right;
            sum += r;
            deviation.push_back(std::abs(r - wall->second.second));
        }
        std::snprintf(line, sizeof line,
                      "report: state %d, %s wall at %.2f m, %zu ticks: reading mean %.3f m; |reading - clearance| "
                      "median %.3f, 90 %% %.3f, max %.3f m (raw ranger readings: door niche and corner included)\n",
                      state, wall->second.first.c_str(), wall->second.second, samples.size(), sum / double(samples.size()),
                      percentile(deviation, 0.5), percentile(deviation, 0.9), percentile(deviation, 1.0));
        out += line;
    }
    return out;
}

namespace {

/// The states that follow a wall: id → (side, clearance), from the checked machine's JSON.
std::map<int, std::pair<std::string, double>> walls_of(const std::string& machine_json)
{
    std::map<int, std::pair<std::string, double>> walls;
    const auto machine = nlohmann::json::parse(machine_json);  // alive through the loop
    for (const auto& st : machine["states"]) {
        if (st["type"].get<std::string>().find("FollowWall") != std::string::npos) {
            walls[st["id"].get<int>()] = {st.value("side", "right"), st.value("clearance", 0.4)};
        }
    }
    return walls;
}

}  // namespace

struct FsmNode::Impl
{
    Impl(FsmNodeOptions o, std::unique_ptr<Machine> m, const std::string& json)
        : options(o), machine(std::move(m)), report(walls_of(json)), states(topics::vehicle_state.name, topics::vehicle_state.reader_for(o.vehicle_id)),
          ranges(topics::range_sensors.name, topics::range_sensors.reader_for(o.vehicle_id)),
          markers(topics::aruco_markers.name, topics::aruco_markers.reader_for(o.vehicle_id)),
          commands(topics::vehicle_command_direct.name, topics::vehicle_command_direct.writer),
          stops(topics::stop_request.name, topics::stop_request.writer), status(topics::fsm_status.name, topics::fsm_status.writer)
    {
    }

    /// The node's last word: the car left braked, unless this very moment's request was sent
    /// already (the last tick of a simulated run, whose clock stands still then). A second one
    /// says nothing new, and written as the process exits (best effort, from its shared memory)
    /// it reached the recorder in some runs and not in others (1 corridor run in about 30).
    /// In real time the node also sees the car stop before it goes: its StopRequest written
    /// just before the process ended was lost in one run of the suite, and the car drove on its
    /// last command until that went stale (1 s, half a metre past the stop). It repeats the
    /// request every 100 ms until a state the car measured after the first says it stands, 2 s
    /// at most, and says so if it never does. A node with no fresh state of its car (none came,
    /// or it is gone) does not wait.
    void brake_and_leave()
    {
        const uint64_t now = get_time_ns();
        if (now != last_stop_sent) brake(now, true);
        if (init_settings().simulated_time) return;
        const uint64_t first = last_stop_sent;
        const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(2);
        for (int k = 1;; ++k) {
            const auto state = states.get_sample(get_time_ns());
            if (!state.valid || state.age_ns > options.max_age_ns) return;
            if (state.sample.header().create_stamp().nanoseconds() > first && std::abs(state.sample.speed()) < 0.02) return;
            if (std::chrono::steady_clock::now() >= deadline) {
                CPM_LOG_WARN("vehicle %u: still at %.2f m/s 2 s after the node's last StopRequest; leaving anyway",
                             unsigned(options.vehicle_id), state.sample.speed());
                return;
            }
            std::this_thread::sleep_for(std::chrono::milliseconds(20));
            if (k % 5 == 0) brake(get_time_ns(), true);
        }
    }

    void brake(uint64_t now, bool force = false)
    {
        if (!force && now - last_stop_sent < 500'000'000ull) return;  // repeated twice a second while braking
        StopRequest s;
        s.vehicle_id(options.vehicle_id);
        stamp_message(s, now, 0);
        {
            std::lock_guard lock(own_stops_mutex);
            own_stops.push_back(now);
            if (own_stops.size() > 16) own_stops.pop_front();
        }
        (void)stops.write(s);
        last_stop_sent = now;
    }
    /// A StopRequest for this car or for all that this node did not send itself (a person at the
    /// monitor, the lab's end): the machine halts and the car stays braked until the node restarts.
    void on_stop_requests(std::vector<StopRequest>& requests)
    {
        std::lock_guard lock(own_stops_mutex);
        for (const auto& r : requests) {
            if (r.vehicle_id() != 0 && r.vehicle_id() != options.vehicle_id) continue;
            const uint64_t stamp = r.header().create_stamp().nanoseconds();
            if (std::find(own_stops.begin(), own_stops.end(), stamp) != own_stops.end()) continue;
            if (stamp < started_ns) continue;  // from before this node ran (a transient sample)
            stopped_by_request = stamp;
        }
    }
    void write_status(uint64_t now, int state_id, const std::string& type, uint64_t entered, int transition)
    {
        FsmStatus s;
        s.vehicle_id(options.vehicle_id);
        stamp_message(s, now, 0);
        s.state_id(state_id);
        s.state_type(type);
        s.entered_ns(entered);
        s.last_transition_id(transition);
        (void)status.write(s);
    }
    void publish_status(uint64_t now)
    {
        write_status(now, machine->active().id(), machine->active().type(), entered_ns, machine->last_transition());
    }
    /// Why the input cannot be used now; empty when it can.
    std::string stale(const SampleResult<VehicleState>& state, const SampleResult<RangeSensors>& range) const
    {
        if (!state.valid) return "no VehicleState";
        if (!range.valid) return "no RangeSensors";
        if (state.age_ns > options.max_age_ns) return "VehicleState is " + std::to_string(state.age_ns / 1'000'000) + " ms old";
        if (range.age_ns > options.max_age_ns) return "RangeSensors is " + std::to_string(range.age_ns / 1'000'000) + " ms old";
        return "";
    }
    /// One timer tick; false when the machine stopped in a final state.
    bool tick();
    /// After a StopRequest: says so once (log and status), and keeps the car braked.
    void halt(uint64_t now);
    /// Why the machine cannot tick now (stale input, a camera's first markers not come); empty when it can.
    std::string not_ready(const SampleResult<VehicleState>& state, const SampleResult<RangeSensors>& range, uint64_t now);
    /// Brakes while `reason` holds (logged when it changes), and says when the input is fresh again.
    bool brake_while(const std::string& reason, uint64_t now);
    /// The machine's active state changed: printed (with what it saw) and published.
    void on_state_change(const Inputs& in, uint64_t now);
    /// The machine's output to the car: a command, or a brake.
    bool apply(const Output& out, uint64_t now);

    FsmNodeOptions options;
    std::unique_ptr<Machine> machine;
    RunReport report;
    Reader<VehicleState> states;
    Reader<RangeSensors> ranges;
    Reader<ArucoMarkers> markers;
    Writer<VehicleCommandDirect> commands;
    Writer<StopRequest> stops;
    Writer<FsmStatus> status;
    const uint64_t started_ns = get_time_ns();
    std::mutex own_stops_mutex;
    std::deque<uint64_t> own_stops;  ///< create_stamps of this node's own StopRequests
    std::atomic<uint64_t> stopped_by_request{0};
    bool halted = false;
    AsyncReader<StopRequest> stop_requests{[this](std::vector<StopRequest>& r) { on_stop_requests(r); }, topics::stop_request.name,
                                           topics::stop_request.reader};
    std::string stale_reason;
    uint64_t last_range_stamp = 0, last_stop_sent = 0;
    uint64_t entered_ns = 0;  ///< when the active state was entered, lab time
    const bool needs_markers = uses_markers(*machine);
    bool markers_came = false;  ///< the first fresh ArucoMarkers came (the machine may start)
    int last_state = -1;
};

void FsmNode::Impl::halt(uint64_t now)
{
    if (!halted) {
        CPM_LOG_WARN("vehicle %u: stopped by a StopRequest; the machine halts in state %d (%s) and the car stays braked until fsm_node "
                     "is started again", unsigned(options.vehicle_id), machine->active().id(), machine->active().type().c_str());
        halted = true;
        write_status(now, -1, "StoppedByRequest", now, -1);
    }
    brake(now);
}

std::string FsmNode::Impl::not_ready(const SampleResult<VehicleState>& state, const SampleResult<RangeSensors>& range, uint64_t now)
{
    std::string reason = stale(state, range);
    // A machine that looks for markers starts once its camera's first markers have come (the
    // camera and its marker finder come up later than the car): driven before, it would pass
    // the gates it has not seen yet. Later a frame's lag is a frame without markers.
    if (reason.empty() && needs_markers && !markers_came) {
        const auto first = markers.get_sample(now);
        markers_came = first.valid && first.age_ns <= options.max_age_ns;
        if (!markers_came) reason = "no ArucoMarkers yet (the machine looks for markers)";
    }
    return reason;
}

bool FsmNode::Impl::brake_while(const std::string& reason, uint64_t now)
{
    const unsigned id = options.vehicle_id;
    if (!reason.empty()) {
        if (reason.substr(0, 8) != stale_reason.substr(0, 8)) {
            CPM_LOG_WARN("vehicle %u: %s; braking until fresh input arrives", id, reason.c_str());
        }
        stale_reason = reason;
        brake(now);
        return true;
    }
    if (!stale_reason.empty()) CPM_LOG_INFO("vehicle %u: input fresh again; running", id);
    stale_reason.clear();
    return false;
}

void FsmNode::Impl::on_state_change(const Inputs& in, uint64_t now)
{
    if (last_state >= 0) {
        std::printf("%.3f vehicle %u: state %d -> %d (%s) by transition %d at %.2f m driven; front %.2f left %.2f right %.2f\n", in.t,
                    unsigned(options.vehicle_id), last_state, machine->active().id(), machine->active().type().c_str(),
                    machine->last_transition(), in.odometer, in.front, in.left, in.right);
        std::fflush(stdout);
    }
    last_state = machine->active().id();
    publish_status(now);
}

bool FsmNode::Impl::apply(const Output& out, uint64_t now)
{
    if (out.brake) {
        brake(now);
        return !machine->in_final_state();
    }
    last_stop_sent = 0;
    VehicleCommandDirect c;
    c.vehicle_id(options.vehicle_id);
    stamp_message(c, now, 0);
    c.motor_throttle(out.throttle);
    c.steering_servo(out.steering);
    (void)commands.write(c);
    return true;
}

bool FsmNode::Impl::tick()
{
    const uint64_t now = get_time_ns();
    if (stopped_by_request) {
        halt(now);
        return true;
    }
    auto state = states.get_sample(now);
    auto range = ranges.get_sample(now);
    if (brake_while(not_ready(state, range, now), now)) return true;
    // The machine ticks once per new range sample: the wall followers' derivative term must
    // see each measurement once (tick_period in the machine = the sensors' period).
    const uint64_t range_stamp = range.sample.header().create_stamp().nanoseconds();
    if (range_stamp == last_range_stamp) return true;
    const double dt = last_range_stamp ? double(range_stamp - last_range_stamp) * 1e-9 : 1.0 / options.rate_hz;
    last_range_stamp = range_stamp;

    auto seen = markers.get_sample(now);
    const bool markers_fresh = seen.valid && seen.age_ns <= options.max_age_ns;
    const Inputs in = inputs_from(state.sample, range.sample, markers_fresh ? &seen.sample : nullptr, double(now) * 1e-9);
    const int ticked_state = machine->active().id();
    auto out = machine->tick(in, dt);
    // The machine keeps its times as seconds in a double (256 ns steps at today's wall clock):
    // the state's entry is kept here as the tick's integer time.
    if (machine->entered_t() == in.t) entered_ns = now;
    report.add(in, ticked_state);
    if (machine->active().id() != last_state) on_state_change(in, now);
    return apply(out, now);
}

FsmNode::FsmNode(FsmNodeOptions options, std::unique_ptr<Machine> machine, const std::string& machine_json)
    : impl_(std::make_unique<Impl>(options, std::move(machine), machine_json))
{
}

FsmNode::~FsmNode() = default;

void FsmNode::run(const std::function<bool()>& stop_requested)
{
    const auto period_ns = static_cast<uint64_t>(1e9 / impl_->options.rate_hz);
    if (impl_->options.tick_on_sample) {
        // Each new range sample ticks at once; a period without one ticks anyway, so that
        // missing or stale input brakes the car as in timer mode.
        while (!stop_requested()) {
            (void)impl_->ranges.wait_for_new_sample(std::chrono::nanoseconds(period_ns));
            if (!impl_->tick()) break;
        }
        impl_->brake_and_leave();
        return;
    }
    const std::string node_id = timer_ids::fsm_node(impl_->options.vehicle_id);
    if (init_settings().simulated_time) {
        // The car's state and ranges, and the markers when the machine looks for gates.
        std::vector<TimerInput> inputs{{topics::vehicle_state.name, [this] { return impl_->states.matched_publications(); }},
                                       {topics::range_sensors.name, [this] { return impl_->ranges.matched_publications(); }}};
        if (uses_markers(*impl_->machine)) {
            inputs.push_back({topics::aruco_markers.name, [this] { return impl_->markers.matched_publications(); }});
        }
        if (!wait_for_inputs(node_id, inputs, stop_requested)) {
            impl_->brake_and_leave();
            return;
        }
    }
    auto timer = Timer::create(node_id, period_ns, 0, cpm::TimerOptions{.wait_for_start = false, .simulated_time_allowed = true});
    timer->run_until(stop_requested, [&](uint64_t) {
        if (!impl_->tick()) timer->stop();
    });
    impl_->brake_and_leave();
}

const Machine& FsmNode::machine() const { return *impl_->machine; }
const RunReport& FsmNode::report() const { return impl_->report; }

}  // namespace cpm::fsm
