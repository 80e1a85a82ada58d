#pragma once
// A run drawn for people: from a run's folder (recording.db, summary.json) the figures of the
// run as numbers and as plots made with gnuplot (PNG files beside report.html):
// - each car's true path on the map (walls, markers, gates, lanes),
// - speed and steering over time, the state machines' states over time,
// - clearance to the nearest wall, the smallest distance between two cars,
// - per-topic rates and delay (create -> commit), the run's warnings and errors.
// The figures go into summary.json under "report" too.
//
// make_report() is three steps: the folder read (a RecordedRun, summary.json, the world),
// figures_of() (the figures from those, without any I/O), report_page() (the page's HTML from
// the figures). The last two are here for tests and tools to drive on their own.
#include <nlohmann/json.hpp>

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace cpm::vehicle {
class World;
}

namespace cpm::lab {

struct Report
{
    std::string html;                 ///< report.html's path
    std::vector<std::string> images;  ///< the plots' paths
    nlohmann::json figures;           ///< what summary.json's "report" holds
};

/// Draws the report of the run in `run_dir`: reads it, figures_of(), the plots, report_page().
/// Throws cpm::Error naming what is missing (the folder, its recording, gnuplot), why the
/// recording cannot be read, or what failed (gnuplot's own message).
Report make_report(const std::string& run_dir);

/// One recorded sample, as the report reads it.
struct RecordedSample
{
    uint64_t data_ns = 0;    ///< its data time: the create stamp, or the writer's source time
    uint64_t commit_ns = 0;  ///< when the history committed it, on the history's real clock
    /// The sample decoded, for the topics the report reads (vehicleObservation, vehicleState,
    /// fsmStatus, log, bookmark); null for the other topics and for a sample that could not be decoded.
    nlohmann::json value;
};

/// One recorded instance (a topic, or one key of a keyed topic), its samples in commit order.
struct RecordedInstance
{
    std::string topic;
    bool stamped = true;  ///< the data time is the sample's create stamp, not the writer's source time
    std::vector<RecordedSample> samples;
};

/// What the report reads from a run's recording.db.
struct RecordedRun
{
    std::vector<RecordedInstance> instances;
    uint64_t samples = 0;     ///< samples loaded
    uint64_t started_ns = 0;  ///< the recording's start: time 0 of the plots when no car sample is recorded
    std::string warning;      ///< why the load stopped early or the file was not closed ("" if neither)
};

/// A car's pose at a time: its true pose (vehicleObservation), else its own estimate (vehicleState).
struct CarPose
{
    double t_s = 0, x_m = 0, y_m = 0, yaw_rad = 0;
};

/// A value at a time. Times of the figures are seconds from the first car sample's data time.
struct TimedValue
{
    double t_s = 0, value = 0;
};

/// A state machine's state, entered at t_s.
struct StateEntered
{
    double t_s = 0;
    std::string state;
};

/// A gate of the world judged on a car's path (aruco::gate_passages); t_s, offset_m (+ left of
/// the gate's centre) and clearance_m (car side to marker) mean something only when passed.
struct GateFigures
{
    int gate = 0;  ///< 1 for the world's first gate
    bool passed = false;
    double t_s = 0, offset_m = 0, clearance_m = 0;
};

/// A car's figures: its series over time and the numbers drawn from them.
struct CarFigures
{
    std::vector<CarPose> path;                 ///< by time
    std::vector<TimedValue> speed_m_s;         ///< vehicleState.speed
    std::vector<TimedValue> steering;          ///< vehicleState.steering_servo, -1 .. 1
    std::vector<TimedValue> clearance_m;       ///< to the nearest wall along the path; empty without walls
    std::vector<StateEntered> states;          ///< fsmStatus, in recorded order
    double driven_m = 0;                       ///< the path's length
    double max_speed_m_s = 0;                  ///< at least 0
    std::optional<double> min_clearance_m;     ///< none without walls
    std::vector<GateFigures> gates;            ///< one per gate of the world; empty without gates
    int gates_passed = 0;
    /// With a positioning system beside the simulator's truth: where the IPS saw the car
    /// (vehicleObservation), its distance from the true pose at the same moment, and the figures.
    std::vector<CarPose> ips;
    std::vector<TimedValue> ips_error_m;
    std::optional<double> ips_error_m_p50, ips_error_m_p99, ips_yaw_error_deg_p99;
};

/// A topic's figures, over all its instances.
struct TopicFigures
{
    uint64_t samples = 0;
    double rate_hz = 0;           ///< (samples - 1) over the time they span; 0 below two samples
    bool per_lab_second = false;  ///< a stamped topic of a simulated run: rate per second of lab time
    /// Create stamp -> commit, real time only (in simulated time they are on two clocks).
    std::optional<double> delay_ms_p50, delay_ms_p99;
};

/// A warning or error of the run's log.
struct LogLine
{
    std::optional<double> t_s;  ///< none: stamped on a clock the lab's time axis cannot place
    bool error = false;         ///< else a warning
    std::string node, text;
};

/// A bookmark (cpm lab mark) on the lab's time axis.
struct MarkFigure
{
    double t_s = 0;
    std::string text, source;
};

/// A host of a run across computers, as summary.json says (its clock against the run's own).
struct HostFigures
{
    std::string name, address;
    double clock_offset_ms = 0, rtt_ms = 0;
    bool lost = false;
};

/// A user's controller as its middleware counted it (summary.json's "controllers").
struct ControllerFigures
{
    std::string name, vehicles;  ///< vehicles as "1, 2, 3"
    uint64_t periods = 0, answered = 0, unanswered = 0, forwarded = 0, refused = 0;
    double response_ms_p50 = 0, response_ms_p99 = 0;
    std::string refusals;  ///< the first refusal of each kind, "; " between
};

/// What a run's report shows: summary.json's outline of the run and the recording's figures.
struct RunFigures
{
    std::string name;        ///< summary's "name"
    std::string time = "?";  ///< summary's "time": "real", "simulated", or "?" when it has none
    double lab_time_s = 0, real_s = 0;
    double clock_real_s = 0;  ///< a simulated run: the real seconds its clock stepped (0: not known)
    bool ok = false;         ///< every process ran its time
    std::string why_not_ok;  ///< why the run did not end well: its error, a stop, a failed process; "" when ok
    uint64_t recorded_samples = 0;
    std::string recording_warning;
    std::map<int, CarFigures> cars;  ///< by vehicle id
    size_t gates_in_world = 0;       ///< 0 in a world without gates (or without a world)
    std::vector<TimedValue> closest_m;                   ///< the two closest cars' distance, every 0.1 s (two cars or more)
    std::optional<double> min_distance_between_cars_m;   ///< the least of closest_m
    std::map<std::string, TopicFigures> topics;          ///< by topic name
    std::map<std::string, uint64_t> missed_ticks_by_timer;  ///< as the timers said in the log, the highest count each
    uint64_t missed_deadlines = 0;   ///< the sum of missed_ticks_by_timer
    std::vector<LogLine> log;        ///< the log's warnings and errors, in recorded order
    size_t log_errors = 0, log_warnings = 0;
    std::vector<HostFigures> hosts;  ///< a run across computers: each host; empty on one host
    std::vector<ControllerFigures> controllers;  ///< users' controllers (cpm::hlc), as their middlewares counted
    std::vector<MarkFigure> marks;   ///< the run's bookmarks, in time order

    bool simulated() const { return time == "simulated"; }
};

/// The figures of a run from its recording, its summary.json and its world (null when it has
/// none or it could not be read). No I/O. O(samples + cars × path × gates + lab seconds × cars²).
/// A summary field of the wrong type throws nlohmann::json::type_error, as make_report does.
RunFigures figures_of(const RecordedRun& recording, const nlohmann::json& summary, const vehicle::World* world = nullptr);

/// The report page, report.html's text, showing `figures` and the plots `images` (file names in
/// the folder plots/ beside the page). Every string of the run (names, states, topics, log
/// lines) is HTML-escaped: the page shows it as text.
std::string report_page(const RunFigures& figures, const std::vector<std::string>& images);

}  // namespace cpm::lab
