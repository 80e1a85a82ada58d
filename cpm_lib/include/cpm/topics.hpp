#pragma once
// The lab's topics in one table: each topic's name on the wire, its type, and the QoS cpm's own
// writers offer and readers ask for. Use an entry instead of spelling the name, so that every
// program agrees on both:
//
//   namespace t = cpm::topics;
//   cpm::Writer<VehicleState> state(t::vehicle_state.name, t::vehicle_state.writer);
//   cpm::Reader<VehicleState> mine(t::vehicle_state.name, t::vehicle_state.reader_for(3));
//
// The names are cpm_lab's where cpm_lab has the topic. The QoS are chosen so that a writer as
// the table says matches every reader as the table says:
//   - sensor data and commands: best effort, the newest sample per vehicle (a late sample is
//     worth less than the next one);
//   - state that a late joiner needs (parameters, a node's status, the lab's start): reliable
//     and transient-local, the newest per key;
//   - requests and replies: reliable, nothing dropped while a service is busy.
#include <cpm/ReaderOptions.hpp>
#include <cpm/WriterOptions.hpp>

#include <array>
#include <string>
#include <cstdint>
#include <string_view>

namespace cpm {

struct TopicSpec
{
    const char* name;       ///< on the wire
    const char* type_name;  ///< the IDL type
    WriterOptions writer;   ///< what cpm's writers offer
    ReaderOptions reader;   ///< what cpm's readers ask for
    const char* about;

    /// The reader's options for one vehicle's samples only.
    constexpr ReaderOptions reader_for(uint8_t vehicle_id) const
    {
        ReaderOptions o = reader;
        o.vehicle_id = vehicle_id;
        return o;
    }
};

namespace topics {

namespace qos {
constexpr WriterOptions reliable_writer(int depth, bool transient_local)
{
    WriterOptions o;
    o.reliable = true;
    o.history_depth = depth;
    o.transient_local = transient_local;
    return o;
}
constexpr ReaderOptions reliable_reader(int depth, bool transient_local, bool keep_all = false)
{
    ReaderOptions o;
    o.reliable = true;
    o.history_depth = depth;
    o.transient_local = transient_local;
    o.keep_all = keep_all;
    return o;
}
/// The lab clock's topics: a simulated clock steps thousands of times a second, each step a
/// sample of depth-1 writers (one heartbeat each). Answered every 20 ms instead of at once, the
/// heartbeats of a step no longer wake every reader's and writer's thread in it.
constexpr ReaderOptions clock_reader()
{
    ReaderOptions o = reliable_reader(64, true);
    o.acknowledge_after = std::chrono::milliseconds(20);
    return o;
}
constexpr ReaderOptions newest_reader(int depth)
{
    ReaderOptions o;
    o.history_depth = depth;
    return o;
}
}  // namespace qos

// ---- vehicles --------------------------------------------------------------------------------
inline constexpr TopicSpec vehicle_state{"vehicleState", "VehicleState", {}, {},
                                         "each car's state at 50 Hz: pose, speed, odometer, IMU, battery"};
inline constexpr TopicSpec range_sensors{"rangeSensors", "RangeSensors", {}, {}, "each car's ultrasonic ranges (front, left, right)"};
inline constexpr TopicSpec vehicle_observation{"vehicleObservation", "VehicleObservation", {}, {},
                                               "each car's pose as seen from outside (the simulator's ground truth, the camera)"};
inline constexpr TopicSpec aruco_markers{"arucoMarkers", "ArucoMarkers", {}, {}, "the markers a car's camera sees in one frame"};
inline constexpr TopicSpec camera_frame{"cameraFrame", "CameraFrame", {}, {}, "a car camera's image, exposure time as create_stamp"};
inline constexpr TopicSpec vehicle_observation_truth{"vehicleObservationTruth", "VehicleObservation", {}, {},
                                                     "each simulated car's true pose when the lab's positioning camera writes vehicleObservation"};
inline constexpr TopicSpec ips_camera_frame{"ipsCameraFrame", "CameraFrame", {}, {},
                                            "the overhead positioning camera's image (vehicle_id 0), exposure time as create_stamp"};
inline constexpr TopicSpec vehicle_command_direct{"vehicleCommandDirect", "VehicleCommandDirect", {}, {},
                                                  "throttle and steering, -1..1"};
inline constexpr TopicSpec vehicle_command_speed_curvature{"vehicleCommandSpeedCurvature", "VehicleCommandSpeedCurvature", {}, {},
                                                           "speed and curvature for the car's controller"};
inline constexpr TopicSpec vehicle_command_trajectory{"vehicleCommandTrajectory", "VehicleCommandTrajectory", {}, {},
                                                      "timed trajectory points for the car to follow"};
inline constexpr TopicSpec vehicle_command_path_tracking{"vehicleCommandPathTracking", "VehicleCommandPathTracking", {}, {},
                                                         "a path and a speed for the car to follow"};
inline constexpr TopicSpec stop_request{"stopRequest", "StopRequest", {}, qos::newest_reader(4), "stop one car, or every car"};
inline constexpr TopicSpec fsm_status{"fsmStatus", "FsmStatus", qos::reliable_writer(1, true), qos::reliable_reader(1, true),
                                      "a state machine's current state and since when"};

/// A high-level controller's input each period (hlc_middleware → the controller, on the
/// controller's own domain; cpm/hlc/Communicator.hpp).
inline constexpr TopicSpec vehicle_state_list{"vehicleStateList", "VehicleStateList", qos::reliable_writer(1, false),
                                              qos::reliable_reader(1, false), "a controller's cars' newest states, each period"};

// ---- every process ---------------------------------------------------------------------------
inline constexpr TopicSpec log{"log", "Log", qos::reliable_writer(100, true), qos::reliable_reader(100, true, true),
                               "log lines of every process"};
inline constexpr TopicSpec log_level{"logLevel", "LogLevel", qos::reliable_writer(1, true), qos::reliable_reader(1, true),
                                     "the lab's log level"};
inline constexpr TopicSpec parameter{"parameter", "Parameter", qos::reliable_writer(1, true), qos::reliable_reader(1, true),
                                     "the parameter server's values, one instance per name"};
inline constexpr TopicSpec parameter_request{"parameterRequest", "ParameterRequest", qos::reliable_writer(10, false),
                                             qos::reliable_reader(100, false), "a node asks for a parameter"};
/// Lab start and stop. A transient-local reader does not match a volatile writer (cpm_lab's LCC
/// writes its SystemTrigger with a plain reliable one), so cpm's timers read these topics twice:
/// with `reader` for what was sent before they matched, and with `reader` made volatile for
/// every sample sent after.
inline constexpr TopicSpec ready_status{"readyStatus", "ReadyStatus", qos::reliable_writer(1, true), qos::clock_reader(),
                                        "a node's timer is ready to start"};
inline constexpr TopicSpec system_trigger{"systemTrigger", "SystemTrigger", qos::reliable_writer(1, true), qos::clock_reader(),
                                          "the lab's start time, or stop"};

// ---- the history -----------------------------------------------------------------------------
inline constexpr TopicSpec history_request{"historyRequest", "HistoryRequest", qos::reliable_writer(64, false),
                                           qos::reliable_reader(1, false, true), "a question to the history service"};
/// Transient-local: a client whose reader matched after the reply went out still gets it.
inline constexpr TopicSpec history_reply{"historyReply", "HistoryReply", qos::reliable_writer(64, true),
                                         qos::reliable_reader(1, true, true), "the history service's answers"};
/// In a secured lab (DDS Security) the history answers a query for samples of topic T on
/// "historyReply/T": only a node whose permissions let it subscribe that topic reads them, so the
/// history is no way around the permissions (cpm security add-node grants "historyReply/T" with T).
inline std::string history_reply_topic(const std::string& topic) { return std::string(history_reply.name) + "/" + topic; }
/// Whether `topic` is the history's own (historyRequest, historyReply, historyReply/T).
inline bool is_history_control(const std::string& topic)
{
    return topic == history_request.name || topic == history_reply.name || topic.rfind(std::string(history_reply.name) + "/", 0) == 0;
}
// ---- the lab's record -------------------------------------------------------------------------
/// Volatile: a bookmark is an event of its moment, recorded by the history that runs then.
inline constexpr TopicSpec bookmark{"bookmark", "Bookmark", qos::reliable_writer(16, false), qos::reliable_reader(64, false, true),
                                    "a moment marked in the run: its text and who marked it"};

inline constexpr TopicSpec history_status{"historyStatus", "HistoryStatus", qos::reliable_writer(1, true),
                                          qos::reliable_reader(1, true), "the history service's counts, once a second"};

inline constexpr std::array all{&vehicle_state,          &range_sensors,          &vehicle_observation,
                                &aruco_markers,          &camera_frame,           &vehicle_observation_truth,
                                &ips_camera_frame,       &vehicle_command_direct,
                                &vehicle_command_speed_curvature, &vehicle_command_trajectory, &vehicle_command_path_tracking,
                                &stop_request,           &fsm_status,             &vehicle_state_list,
                                &log,
                                &log_level,              &parameter,              &parameter_request,
                                &ready_status,           &system_trigger,         &history_request,
                                &history_reply,          &history_status,         &bookmark};

/// The entry of a name, or nullptr.
constexpr const TopicSpec* find(std::string_view name)
{
    for (const TopicSpec* t : all) {
        if (name == t->name) return t;
    }
    return nullptr;
}

}  // namespace topics
}  // namespace cpm
