// fsm_node: runs a car's state machine against its VehicleState and RangeSensors (and
// ArucoMarkers when a camera publishes them) and commands it with VehicleCommandDirect.
#include <cpm/CommandLine.hpp>
#include <cpm/Logging.hpp>
#include <cpm/Participant.hpp>
#include <cpm/Reader.hpp>
#include <cpm/Timer.hpp>
#include <cpm/Writer.hpp>
#include <cpm/fsm/Loader.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/init.hpp>
#include <cpm/stamp_message.hpp>

#include <ArucoMarkers.h>
#include <FsmStatus.h>
#include <RangeSensors.h>
#include <StopRequest.h>
#include <VehicleCommandDirect.h>
#include <VehicleState.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <csignal>
#include <map>
#include <cstdio>
#include <string>

namespace {

const char* kHelp =
    "usage: fsm_node --vehicle_id N --fsm FILE.json|FILE.uxf [--rate 80] [--max-age 200ms] [--report] [--dds_domain N]\n"
    "\n"
    "Loads and checks the state machine (all errors at once, exit 1), then looks at --rate Hz\n"
    "(cpm::Timer) for a new RangeSensors sample of vehicle N and ticks the machine once per\n"
    "sample (set the machine's tick_period to the sensors' period, 0.02 s for a bridge) against\n"
    "the newest valid VehicleState and RangeSensors (and\n"
    "ArucoMarkers, when present), writes VehicleCommandDirect for vehicle N, publishes FsmStatus\n"
    "on every state change and prints each transition. Stop states and missing or stale input\n"
    "(older than --max-age) brake the car with a StopRequest; the reason is logged.\n"
    "Ends on SIGINT/SIGTERM (braking the car) or when the machine stops in a final Stop state.\n"
    "--report: at the end, print the distance driven, the heading change and, for each wall\n"
    "following state, the followed range's mean and deviation from its clearance.\n";

/// What --report prints at the end: distance, heading change, and per wall-following state the
/// followed range against its clearance.
class RunReport
{
public:
    void add(const cpm::fsm::Inputs& in, int state)
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
    void print() const;
    void set_walls(std::map<int, std::pair<std::string, double>> walls) { walls_ = std::move(walls); }

private:
    bool started_ = false;
    double start_odometer_ = 0, start_yaw_ = 0, odometer_ = 0, yaw_ = 0;
    std::map<int, std::vector<std::pair<double, double>>> ranges_;
    std::map<int, std::pair<std::string, double>> walls_;  // state -> (side, clearance)
};

void RunReport::print() const
{
    double turned = std::remainder(yaw_ - start_yaw_, 2 * M_PI) * 180 / M_PI;
    std::printf("report: driven %.2f m, heading changed by %.0f deg\n", odometer_ - start_odometer_, turned);
    for (const auto& [state, samples] : ranges_) {
        auto wall = walls_.find(state);
        if (wall == walls_.end() || samples.empty()) continue;
        double sum = 0;
        std::vector<double> deviation;
        for (const auto& [left, right] : samples) {
            double r = wall->second.first == "left" ? left : right;
            sum += r;
            deviation.push_back(std::abs(r - wall->second.second));
        }
        std::sort(deviation.begin(), deviation.end());
        auto at = [&](double q) { return deviation[std::min(deviation.size() - 1, size_t(q * double(deviation.size())))]; };
        std::printf("report: state %d, %s wall at %.2f m, %zu ticks: reading mean %.3f m; |reading - clearance| "
                    "median %.3f, 90 %% %.3f, max %.3f m (raw ranger readings: door niche and corner included)\n",
                    state, wall->second.first.c_str(), wall->second.second, samples.size(), sum / double(samples.size()),
                    at(0.5), at(0.9), deviation.back());
    }
}

int run(int argc, char** argv)
{
    std::vector<std::string> args(argv + 1, argv + argc);
    auto parsed = cpm::cli::parse_args(
        args, {{"--vehicle_id", true}, {"--fsm", true}, {"--rate", true}, {"--max-age", true}, {"--report", false}}, "fsm_node");
    if (!parsed.positional.empty()) throw cpm::cli::UsageError("fsm_node: unexpected argument '" + parsed.positional[0] + "'");
    if (!parsed.has("--vehicle_id")) throw cpm::cli::UsageError("fsm_node: --vehicle_id is required");
    if (!parsed.has("--fsm")) throw cpm::cli::UsageError("fsm_node: --fsm is required (a machine's JSON file)");
    auto id = static_cast<uint8_t>(cpm::cli::parse_integer("--vehicle_id", parsed.get("--vehicle_id"), 1, 255));
    double rate = cpm::cli::parse_number("--rate", parsed.get("--rate", "80"), 1, 1000);
    uint64_t max_age = cpm::cli::parse_duration("--max-age", parsed.get("--max-age", "200ms"));

    auto loaded = cpm::fsm::load_file(parsed.get("--fsm"));
    for (const auto& w : loaded.warnings) std::fprintf(stderr, "fsm_node: warning: %s\n", w.text().c_str());
    if (!loaded.ok()) {
        for (const auto& e : loaded.errors) std::fprintf(stderr, "fsm_node: error: %s\n", e.text().c_str());
        std::fprintf(stderr, "fsm_node: %zu error(s) in %s; not started\n", loaded.errors.size(), parsed.get("--fsm").c_str());
        return 1;
    }
    cpm::fsm::Machine& machine = *loaded.machine;
    std::map<int, std::pair<std::string, double>> walls;  // for --report: which states follow which wall
    const auto machine_json = nlohmann::json::parse(loaded.json);  // kept: the loop below reads into it
    for (const auto& st : machine_json["states"]) {
        if (st["type"].get<std::string>().find("FollowWall") != std::string::npos) {
            walls[st["id"].get<int>()] = {st.value("side", "right"), st.value("clearance", 0.4)};
        }
    }
    cpm::init(argc, argv);

    cpm::Reader<VehicleState> states("vehicleState", {.vehicle_id = id});
    cpm::Reader<RangeSensors> ranges("rangeSensors", {.vehicle_id = id});
    cpm::Reader<ArucoMarkers> markers("arucoMarkers", {.vehicle_id = id});
    cpm::Writer<VehicleCommandDirect> commands("vehicleCommandDirect");
    cpm::Writer<StopRequest> stops("stopRequest");
    cpm::Writer<FsmStatus> status("fsmStatus", {.reliable = true, .history_depth = 1, .transient_local = true});

    const auto period_ns = static_cast<uint64_t>(1e9 / rate);
    auto timer = cpm::Timer::create("fsm_node_" + std::to_string(id), period_ns, 0, false, false);
    RunReport report;
    report.set_walls(walls);
    std::string stale_reason;
    uint64_t last_range_stamp = 0;
    uint64_t last_stop_sent = 0;
    int last_state = -1;
    auto brake = [&](uint64_t now, bool force = false) {
        if (!force && now - last_stop_sent < 500'000'000ull) return;  // repeated twice a second while braking
        StopRequest s;
        s.vehicle_id(id);
        cpm::stamp_message(s, now, 0);
        stops.write(s);
        last_stop_sent = now;
    };
    auto publish_status = [&](uint64_t now) {
        FsmStatus s;
        s.vehicle_id(id);
        cpm::stamp_message(s, now, 0);
        s.state_id(machine.active().id());
        s.state_type(machine.active().type());
        s.entered_ns(static_cast<uint64_t>(machine.entered_t() * 1e9));
        s.last_transition_id(machine.last_transition());
        status.write(s);
    };

    cpm::cli::stop_on_signals();
    timer->start([&](uint64_t) {
        if (cpm::cli::stop_requested()) {
            timer->stop();
            return;
        }
        const uint64_t now = cpm::get_time_ns();
        auto state = states.get_sample(now);
        auto range = ranges.get_sample(now);
        std::string reason;
        if (!state.valid) reason = "no VehicleState";
        else if (!range.valid) reason = "no RangeSensors";
        else if (state.age_ns > max_age) reason = "VehicleState is " + std::to_string(state.age_ns / 1'000'000) + " ms old";
        else if (range.age_ns > max_age) reason = "RangeSensors is " + std::to_string(range.age_ns / 1'000'000) + " ms old";
        if (!reason.empty()) {
            if (reason.substr(0, 8) != stale_reason.substr(0, 8)) {
                CPM_LOG_WARN("vehicle %u: %s; braking until fresh input arrives", unsigned(id), reason.c_str());
            }
            stale_reason = reason;
            brake(now);
            return;
        }
        if (!stale_reason.empty()) CPM_LOG_INFO("vehicle %u: input fresh again; running", unsigned(id));
        stale_reason.clear();
        // The machine ticks once per new range sample: the wall followers' derivative term
        // must see each measurement once (tick_period in the machine = the sensors' period).
        const uint64_t range_stamp = range.sample.header().create_stamp().nanoseconds();
        if (range_stamp == last_range_stamp) return;
        const double dt = last_range_stamp ? double(range_stamp - last_range_stamp) * 1e-9 : 1.0 / rate;
        last_range_stamp = range_stamp;

        cpm::fsm::Inputs in;
        in.t = double(now) * 1e-9;
        in.odometer = state.sample.odometer_distance();
        in.yaw = state.sample.pose().yaw();
        in.speed = state.sample.speed();
        in.front = range.sample.front();
        in.left = range.sample.left();
        in.right = range.sample.right();
        auto seen = markers.get_sample(now);
        if (seen.valid && seen.age_ns <= max_age) {
            for (const auto& m : seen.sample.markers()) {
                in.markers.push_back({m.id(), m.pose().x(), m.pose().y(), m.pose().yaw(), m.distance()});
            }
        }
        const int ticked_state = machine.active().id();
        auto out = machine.tick(in, dt);
        report.add(in, ticked_state);
        if (machine.active().id() != last_state) {
            if (last_state >= 0) {
                std::printf("%.3f vehicle %u: state %d -> %d (%s) by transition %d at %.2f m driven; front %.2f left %.2f right %.2f\n",
                            in.t, unsigned(id), last_state, machine.active().id(), machine.active().type().c_str(),
                            machine.last_transition(), in.odometer, in.front, in.left, in.right);
                std::fflush(stdout);
            }
            last_state = machine.active().id();
            publish_status(now);
        }
        if (out.brake) {
            brake(now);
            if (machine.in_final_state()) timer->stop();
            return;
        }
        last_stop_sent = 0;
        VehicleCommandDirect c;
        c.vehicle_id(id);
        cpm::stamp_message(c, now, 0);
        c.motor_throttle(out.throttle);
        c.steering_servo(out.steering);
        commands.write(c);
    });
    brake(cpm::get_time_ns(), true);  // leave the car braked
    if (parsed.has("--report")) report.print();
    std::printf("fsm_node: vehicle %u ended in state %d (%s)\n", unsigned(id), machine.active().id(),
                machine.active().type().c_str());
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "fsm_node", kHelp, run); }
