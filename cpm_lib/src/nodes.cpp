#include <cpm/nodes.hpp>

#include <cpm/Error.hpp>
#include <cpm/timer_ids.hpp>
#include <cpm/topics.hpp>

#include <fnmatch.h>

#include <algorithm>

namespace cpm::nodes {

namespace {

namespace t = cpm::topics;

std::string pattern(const TopicSpec& topic, const char* suffix) { return std::string(topic.name) + suffix; }

std::vector<NodeSpec> make_table()
{
    const std::vector<std::string> commands{t::vehicle_command_direct.name, t::vehicle_command_speed_curvature.name,
                                            t::vehicle_command_trajectory.name, t::vehicle_command_path_tracking.name};
    auto with = [](std::vector<std::string> a, const std::vector<std::string>& b) {
        for (const auto& x : b) {
            if (std::find(a.begin(), a.end(), x) == a.end()) a.push_back(x);
        }
        return a;
    };
    std::vector<NodeSpec> rows{
        // ---- the parts every program has --------------------------------------------------
        {.name = "logging", .publish = {t::log.name}, .subscribe = {t::log_level.name}, .about = "its log lines, at the lab's level"},
        {.name = "lab_timer", .publish = {t::ready_status.name}, .subscribe = {t::system_trigger.name}, .steers_the_lab = true,
         .about = "its timer says it is ready and waits for the lab's start"},
        {.name = "parameter_client", .publish = {t::parameter_request.name}, .subscribe = {t::parameter.name}, .steers_the_lab = true,
         .about = "asks for parameters and hears their changes"},
        {.name = "history_client", .publish = {t::history_request.name}, .subscribe = {pattern(t::history_reply, "*")}, .steers_the_lab = true,
         .about = "asks the history for the past"},
        // ---- the programs ----------------------------------------------------------------------
        {.name = "firmware_sim", .publish = {t::vehicle_observation.name, t::vehicle_observation_truth.name},
         .subscribe = {t::vehicle_observation.name, t::vehicle_observation_truth.name},  // the other cars, for its rangers
         .timer = timer_ids::firmware_sim, .about = "a simulated car's firmware: its ground truth"},
        {.name = "firmware_hil", .publish = {t::vehicle_observation.name, t::vehicle_observation_truth.name},
         .subscribe = {t::vehicle_observation.name, t::vehicle_observation_truth.name},  // the other cars, for its rangers
         .timer = timer_ids::firmware_sim,  // the car's microcontroller slot on the lab clock, as firmware_sim's
         .about = "a car's real AVR firmware in simavr, a model car on its pins: its ground truth"},
        {.name = "vehicle_bridge", .publish = {t::vehicle_state.name, t::range_sensors.name},
         .subscribe = with(commands, {t::stop_request.name, t::vehicle_observation.name}), .timer = timer_ids::vehicle_bridge,
         .about = "a car's serial link to DDS: its state and ranges out, commands in"},
        {.name = "camera_sim", .publish = {t::camera_frame.name, t::ips_camera_frame.name},
         .subscribe = {t::vehicle_observation.name, t::vehicle_observation_truth.name}, .timer = timer_ids::camera_sim,
         .about = "a car's simulated camera, or the overhead positioning camera (--overhead)"},
        {.name = "ips_node", .publish = {t::vehicle_observation.name}, .subscribe = {t::ips_camera_frame.name},
         .timer = [](int) { return std::string(timer_ids::ips_node); },
         .about = "the lab's positioning system: every car's pose from the overhead camera's frames"},
        {.name = "aruco_node", .publish = {t::aruco_markers.name}, .subscribe = {t::camera_frame.name}, .timer = timer_ids::aruco_node,
         .about = "finds ArUco markers in a car's camera frames"},
        {.name = "fsm_node", .publish = {t::vehicle_command_direct.name, t::fsm_status.name, t::stop_request.name},
         .subscribe = {t::vehicle_state.name, t::range_sensors.name, t::aruco_markers.name, t::stop_request.name},
         .timer = timer_ids::fsm_node, .about = "a car's JSON state machine"},
        {.name = "central_routing", .publish = {t::vehicle_command_trajectory.name}, .subscribe = {t::vehicle_state.name},
         .timer = [](int) { return std::string(timer_ids::central_routing); }, .about = "plans every car's trajectory on the lane graph"},
        {.name = "hlc_middleware", .publish = with(commands, {t::vehicle_state_list.name}), .subscribe = {t::vehicle_state.name, t::vehicle_observation.name},
         .about = "between a user's high-level controller on its own domain and the lab: lists out, checked commands in"},
        {.name = "hlc_controller", .about = "a user's high-level controller (cpm::hlc::Communicator), on a domain of its own with its middleware"},
        {.name = "cpm_history", .publish = {pattern(t::history_reply, "*"), t::history_status.name}, .subscribe = {"*"},
         .steers_the_lab = true, .about = "keeps the last seconds of every topic, records a run"},
        {.name = "parameter_server", .publish = {t::parameter.name}, .subscribe = {t::parameter_request.name}, .steers_the_lab = true,
         .about = "cpm param serve: the lab's parameters"},
        {.name = "monitor", .publish = {t::stop_request.name, t::bookmark.name}, .subscribe = {"*"},
         .about = "cpm monitor: the lab's page (writes stop requests only with --allow-stop)"},
        {.name = "lab_clock", .publish = {t::system_trigger.name}, .subscribe = {t::ready_status.name}, .steers_the_lab = true,
         .about = "cpm lab clock: starts the lab's timers once every named one is ready, and stops them"},
        {.name = "controller", .publish = commands,
         .subscribe = {t::vehicle_state.name, t::vehicle_observation.name, t::range_sensors.name, t::stop_request.name},
         .about = "a user's controller (examples/vehicle_drive): commands to its cars, their states in"},
        {.name = "lab_run", .publish = {t::stop_request.name, t::system_trigger.name, t::bookmark.name},
         .subscribe = {t::log.name, t::history_status.name, t::ready_status.name, t::vehicle_state.name},
         .about = "cpm lab run: starts, clocks and stops a run (real time from every car's first state)"},
    };
    // `cpm vehicle sim`: a simulator and a bridge in one process group, one node in a secured lab.
    auto row = [&](const char* name) { return *std::find_if(rows.begin(), rows.end(), [&](const NodeSpec& n) { return n.name == name; }); };
    const NodeSpec sim = row("firmware_sim"), bridge = row("vehicle_bridge");
    rows.push_back({.name = "vehicle_sim", .publish = with(sim.publish, bridge.publish), .subscribe = with(sim.subscribe, bridge.subscribe),
                    .about = "cpm vehicle sim: simulated cars with their bridges"});
    return rows;
}

constexpr size_t kParts = 4;  // the first rows: what every program has

std::vector<std::string> joined(std::initializer_list<const char*> names, bool publish)
{
    std::vector<std::string> out;
    for (const char* n : names) {
        const auto& row = find(n);
        const auto& list = publish ? row.publish : row.subscribe;
        out.insert(out.end(), list.begin(), list.end());
    }
    return out;
}

}  // namespace

const std::vector<NodeSpec>& all()
{
    static const std::vector<NodeSpec> table = make_table();
    return table;
}

const NodeSpec& find(std::string_view name)
{
    for (const auto& n : all()) {
        if (n.name == name) return n;
    }
    std::string known;
    for (const auto& k : kinds()) known += (known.empty() ? "" : ", ") + k;
    throw Error("no node kind '" + std::string(name) + "' (known: " + known + ")");
}

std::vector<std::string> kinds()
{
    std::vector<std::string> out;
    for (size_t i = kParts; i < all().size(); ++i) out.push_back(all()[i].name);
    return out;
}

std::vector<std::string> builtin_publish() { return joined({"logging", "lab_timer", "parameter_client"}, true); }
std::vector<std::string> builtin_subscribe() { return joined({"logging", "lab_timer", "parameter_client"}, false); }

std::vector<std::string> control_topics()
{
    std::vector<std::string> out;
    for (const auto& n : all()) {
        if (!n.steers_the_lab) continue;
        for (const auto& t : n.publish) {
            if (std::find(out.begin(), out.end(), t) == out.end()) out.push_back(t);
        }
    }
    return out;
}

bool matches(const std::string& topic, const std::vector<std::string>& patterns)
{
    return std::any_of(patterns.begin(), patterns.end(), [&](const std::string& p) { return ::fnmatch(p.c_str(), topic.c_str(), 0) == 0; });
}

}  // namespace cpm::nodes
