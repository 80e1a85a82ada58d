#include <cpm/lab/Report.hpp>
#include <cpm/lab/Run.hpp>

#include "PageTemplate.hpp"

#include <cpm/ChildProcess.hpp>
#include <cpm/Error.hpp>
#include <cpm/topics.hpp>
#include <cpm/aruco/GateCourse.hpp>
#include <cpm/vehicle/VehicleModel.hpp>
#include <cpm/vehicle/World.hpp>
#include <cpm/Timer.hpp>
#include <cpm/percentile.hpp>
#include <cpm/rtdb/IdlDecoder.hpp>
#include <cpm/rtdb/Recording.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>
#include <unistd.h>

namespace cpm::lab {

namespace fs = std::filesystem;

namespace {

/// A stamp at or after 2001-09-09 is on the real clock (ns since 1970); the lab's simulated
/// clock counts from 0 at the run's start.
constexpr uint64_t kRealClockSince = 1'000'000'000'000'000'000ull;

using Line = std::vector<std::pair<double, double>>;

// ---- What the run's folder holds -------------------------------------------------------------

/// A run's folder, read for its report.
struct RunFolder
{
    nlohmann::json summary;               ///< summary.json as it is; {} when missing or not JSON
    RecordedRun recording;
    std::optional<vehicle::World> world;  ///< read and checked once: its walls, markers and gates
    std::vector<Line> lanes;              ///< the lane graph's edges
};

nlohmann::json read_json(const std::string& path)
{
    std::ifstream in(path);
    if (!in) return nullptr;
    try {
        return nlohmann::json::parse(in);
    } catch (const std::exception&) {
        return nullptr;
    }
}

/// The topics figures_of() reads the samples of, and the members of those samples it reads: the
/// rest is dropped as the recording is read, so that a long run's samples fit in memory.
bool read_for_figures(const std::string& topic)
{
    return topic == topics::vehicle_observation.name || topic == topics::vehicle_observation_truth.name || topic == topics::vehicle_state.name ||
           topic == topics::fsm_status.name ||
           topic == topics::log.name || topic == topics::bookmark.name;
}

nlohmann::json members_for_figures(nlohmann::json sample)
{
    static const std::set<std::string> members{"vehicle_id", "pose", "speed", "steering_servo", "state_type", "log_level", "stamp", "id", "content", "text", "source"};
    nlohmann::json kept = nlohmann::json::object();
    for (auto& member : sample.items()) {
        if (members.count(member.key())) kept[member.key()] = std::move(member.value());
    }
    return kept;
}

RecordedRun read_recording(const rtdb::LoadedRecording& rec, const rtdb::IdlDecoder& types)
{
    RecordedRun run{.samples = rec.samples, .started_ns = rec.started_ns, .warning = rec.warning};
    for (const auto& o : rec.store->search({.kind = rtdb::ObjectKind::instance})) {
        RecordedInstance instance{.topic = o.topic, .stamped = o.data_time == "create_stamp"};
        const bool decode = read_for_figures(o.topic);
        for (const auto& s : rec.store->range(o.oid, 0, UINT64_MAX, rtdb::By::commit, 100'000'000).samples) {
            RecordedSample sample{.data_ns = s.data_ns, .commit_ns = s.commit_ns};
            if (decode) {
                if (auto j = types.decode(o.type_name, s.payload)) sample.value = members_for_figures(std::move(*j));
            }
            instance.samples.push_back(std::move(sample));
        }
        run.instances.push_back(std::move(instance));
    }
    return run;
}

/// The recording, or a cpm::Error with the reader's message.
rtdb::LoadedRecording load(const std::string& path)
{
    try {
        return rtdb::load_recording(path);
    } catch (const Error&) {
        throw;
    } catch (const std::runtime_error& e) {
        throw Error(e.what());
    }
}

/// The world summary.json names, if it names one that can be read.
std::optional<vehicle::World> world_of(const nlohmann::json& summary)
{
    if (!summary.contains("world") || !summary.at("world").is_string() || summary.at("world").get<std::string>().empty()) return std::nullopt;
    try {
        return vehicle::World::load(summary.at("world"));
    } catch (const std::exception&) {
        return std::nullopt;  // a world that cannot be read: the report is drawn without the map
    }
}

std::vector<Line> lanes_of(const nlohmann::json& summary)
{
    std::vector<Line> lanes;
    if (!summary.contains("lanes") || !summary.at("lanes").is_string()) return lanes;
    const auto graph = read_json(summary.at("lanes"));
    if (!graph.is_object()) return lanes;
    for (const auto& e : graph.value("edges", nlohmann::json::array())) {
        Line line;
        for (const auto& p : e["points"]) line.emplace_back(p[0], p[1]);
        lanes.push_back(std::move(line));
    }
    return lanes;
}

RunFolder read_run_folder(const std::string& run_dir)
{
    const fs::path dir(run_dir);
    if (!fs::is_directory(dir)) throw Error("no run folder " + run_dir);
    const std::string recording = (dir / "recording.db").string();
    if (!fs::exists(recording)) throw Error(run_dir + " holds no recording.db");
    if (::access("/usr/bin/gnuplot", X_OK) != 0) throw Error("gnuplot is not installed (Debian package gnuplot-nox; ./lab installs it)");
    const auto rec = load(recording);
    if (rec.samples == 0) {
        // Nothing to draw: say why instead of handing gnuplot empty data ("x range is invalid").
        throw Error(recording + " holds no samples" + (rec.warning.empty() ? "" : ": " + rec.warning));
    }
    const rtdb::IdlDecoder* types = rec.types ? rec.types.get() : rtdb::IdlDecoder::lab_types();
    if (!types) throw Error(recording + " carries no IDL and none is installed");
    RunFolder run{.summary = read_json((dir / "summary.json").string()), .recording = read_recording(rec, *types)};
    if (run.summary.is_null()) run.summary = nlohmann::json::object();
    run.world = world_of(run.summary);
    run.lanes = lanes_of(run.summary);
    return run;
}

/// summary.json with the run folder's name as the run's name when it gives none.
nlohmann::json named(nlohmann::json summary, const std::string& folder)
{
    if (summary.is_object() && !summary.contains("name")) summary["name"] = folder;
    return summary;
}

// ---- The figures -------------------------------------------------------------------------------

/// Why a run did not end well, as summary.json says it: its error, or that it was stopped early.
std::string why_not_ok(const nlohmann::json& summary)
{
    const std::string error = summary.value("error", std::string());
    if (!error.empty()) return error;
    if (summary.value("interrupted", false)) return "it was stopped (Ctrl-C or SIGTERM) before its end";
    for (const auto& p : summary.value("processes", nlohmann::json::array())) {
        if (p.value("failed", false)) return p.value("name", std::string("a process")) + " " + p.value("end", std::string("failed"));
    }
    return "see summary.json";
}

/// The run as summary.json outlines it.
RunFigures outline_of(const nlohmann::json& summary)
{
    RunFigures f;
    f.name = summary.value("name", std::string());
    f.time = summary.value("time", std::string("?"));
    f.lab_time_s = summary.value("lab_time_s", 0.0);
    f.real_s = summary.value("real_s", 0.0);
    f.clock_real_s = summary.value("clock_real_s", 0.0);
    f.ok = summary.value("ok", false);
    if (!f.ok) f.why_not_ok = why_not_ok(summary);
    for (const auto& h : summary.value("hosts", nlohmann::json::array())) {
        f.hosts.push_back({.name = h.value("name", std::string("?")),
                           .address = h.value("address", std::string()),
                           .clock_offset_ms = double(h.value("clock_offset_ns", int64_t(0))) / 1e6,
                           .rtt_ms = double(h.value("rtt_ns", int64_t(0))) / 1e6,
                           .lost = h.value("lost", false)});
    }
    for (const auto& c : summary.value("controllers", nlohmann::json::array())) {
        ControllerFigures cf{.name = c.value("controller", std::string("?"))};
        for (const auto& v : c.value("vehicles", nlohmann::json::array())) cf.vehicles += (cf.vehicles.empty() ? "" : ", ") + v.dump();
        cf.periods = c.value("periods", uint64_t{0});
        cf.answered = c.value("answered", uint64_t{0});
        cf.unanswered = c.value("unanswered", uint64_t{0});
        cf.forwarded = c.value("forwarded", uint64_t{0});
        cf.refused = c.value("refused", uint64_t{0});
        cf.response_ms_p50 = c.value("response_ms_p50", 0.0);
        cf.response_ms_p99 = c.value("response_ms_p99", 0.0);
        const nlohmann::json first = c.value("first_refusals", nlohmann::json::object());  // kept: items() refers to it
        for (const auto& [kind, text] : first.items()) {
            cf.refusals += (cf.refusals.empty() ? "" : "; ") + kind + ": " + text.get<std::string>();
        }
        if (c.contains("error")) cf.refusals = c.value("error", std::string());
        f.controllers.push_back(std::move(cf));
    }
    return f;
}

/// In simulated time the stamps are lab time and the commits the history's real clock: a
/// stamped topic's rate is per lab second there, and create -> commit means nothing.
std::map<std::string, TopicFigures> topic_figures(const RecordedRun& recording, bool simulated)
{
    struct Span
    {
        uint64_t samples = 0, first = std::numeric_limits<uint64_t>::max(), last = 0;
        std::vector<double> delay_ms;
        bool stamped = true;
    };
    std::map<std::string, Span> spans;
    for (const auto& o : recording.instances) {
        auto& s = spans[o.topic];
        s.stamped = o.stamped;
        const bool lab_clock = simulated && o.stamped;
        for (const auto& x : o.samples) {
            ++s.samples;
            s.first = std::min(s.first, lab_clock ? x.data_ns : x.commit_ns);
            s.last = std::max(s.last, lab_clock ? x.data_ns : x.commit_ns);
            if (o.stamped && !simulated && x.commit_ns >= x.data_ns) s.delay_ms.push_back(double(x.commit_ns - x.data_ns) * 1e-6);
        }
    }
    std::map<std::string, TopicFigures> topics;
    for (const auto& [name, s] : spans) {
        TopicFigures& t = topics[name];
        t.samples = s.samples;
        t.rate_hz = s.last > s.first ? double(s.samples - 1) / (double(s.last - s.first) * 1e-9) : 0.0;
        t.per_lab_second = simulated && s.stamped;
        if (!s.delay_ms.empty()) {
            t.delay_ms_p50 = percentile(s.delay_ms, 0.5);
            t.delay_ms_p99 = percentile(s.delay_ms, 0.99);
        }
    }
    return topics;
}

/// The figures' time 0: the first car sample's data time, else the recording's start.
uint64_t lab_zero_ns(const RecordedRun& recording)
{
    uint64_t t0 = std::numeric_limits<uint64_t>::max();
    for (const auto& o : recording.instances) {
        if (o.topic != topics::vehicle_observation.name && o.topic != topics::vehicle_state.name) continue;
        for (const auto& s : o.samples) t0 = std::min(t0, s.data_ns);
    }
    return t0 == std::numeric_limits<uint64_t>::max() ? recording.started_ns : t0;
}

double seconds_since(uint64_t t0, uint64_t t)
{
    return t >= t0 ? double(t - t0) * 1e-9 : -double(t0 - t) * 1e-9;
}

/// A log sample: a warning or an error to list, a timer's missed ticks to count.
void read_log_sample(const nlohmann::json& j, const RecordedSample& s, uint64_t t0, bool simulated, RunFigures& f)
{
    const int level = j.value("log_level", 3);
    // Simulated: a node on the lab clock stamps lab time; one on the real clock (the history)
    // cannot be placed on the lab's time axis.
    const uint64_t stamp = j.value(nlohmann::json::json_pointer("/stamp/nanoseconds"), uint64_t{0});
    if (level <= 2) {
        LogLine line{.error = level == 1, .node = j.value("id", ""), .text = j.value("content", "")};
        if (!simulated) line.t_s = seconds_since(t0, s.commit_ns);
        else if (stamp < kRealClockSince) line.t_s = seconds_since(t0, stamp);
        f.log.push_back(std::move(line));
    }
    if (const auto missed = timer_missed_ticks(j.value("content", ""))) {
        uint64_t& most = f.missed_ticks_by_timer[missed->first];
        most = std::max(most, missed->second);
    }
}

/// A car's sample of vehicleObservation, vehicleState or fsmStatus at lab time t.
void read_car_sample(const std::string& topic, const nlohmann::json& j, double t, bool path_topic, bool ips_topic, RunFigures& f)
{
    CarFigures& car = f.cars[j.value("vehicle_id", 0)];
    if (path_topic || ips_topic) {
        const auto& pose = j.at("pose");
        (path_topic ? car.path : car.ips).push_back({.t_s = t, .x_m = pose.value("x", 0.0), .y_m = pose.value("y", 0.0), .yaw_rad = pose.value("yaw", 0.0)});
    }
    if (topic == topics::vehicle_state.name) {
        car.speed_m_s.push_back({.t_s = t, .value = j.value("speed", 0.0)});
        car.steering.push_back({.t_s = t, .value = j.value("steering_servo", 0.0)});
    }
    if (topic == topics::fsm_status.name) car.states.push_back({.t_s = t, .state = j.value("state_type", std::string("?"))});
}

/// The cars' series and the log's lines; a car's path is its true one (the simulator's
/// vehicleObservationTruth beside a positioning system, else vehicleObservation) when the run
/// recorded any, else its own estimate (vehicleState). Beside the truth, vehicleObservation is
/// the positioning system's view.
void read_samples(const RecordedRun& recording, RunFigures& f)
{
    const uint64_t t0 = lab_zero_ns(recording);
    auto recorded = [&](const char* topic) {
        return std::any_of(recording.instances.begin(), recording.instances.end(), [&](const RecordedInstance& o) { return o.topic == topic; });
    };
    const bool truth = recorded(topics::vehicle_observation_truth.name);
    const bool observed = truth || recorded(topics::vehicle_observation.name);
    const std::string path = truth ? topics::vehicle_observation_truth.name : observed ? topics::vehicle_observation.name : topics::vehicle_state.name;
    for (const auto& o : recording.instances) {
        const bool path_topic = o.topic == path;
        const bool ips_topic = truth && o.topic == topics::vehicle_observation.name;
        if (!path_topic && !ips_topic && o.topic != topics::vehicle_state.name && o.topic != topics::fsm_status.name && o.topic != topics::log.name) {
            continue;
        }
        for (const auto& s : o.samples) {
            if (s.value.is_null()) continue;
            if (o.topic == topics::log.name) read_log_sample(s.value, s, t0, f.simulated(), f);
            else read_car_sample(o.topic, s.value, seconds_since(t0, s.data_ns), path_topic, ips_topic, f);
        }
    }
}

/// The positioning system's error: each IPS pose against the true pose at its moment (linear
/// between the two true poses around it; none outside the truth's span).
void judge_ips(CarFigures& car)
{
    std::sort(car.ips.begin(), car.ips.end(), [](const CarPose& a, const CarPose& b) { return a.t_s < b.t_s; });
    std::vector<double> metres, degrees;
    for (const auto& seen : car.ips) {
        auto after = std::lower_bound(car.path.begin(), car.path.end(), seen.t_s, [](const CarPose& p, double t) { return p.t_s < t; });
        if (after == car.path.end() || (after == car.path.begin() && after->t_s > seen.t_s)) continue;
        const CarPose& b = *after;
        const CarPose& a = after == car.path.begin() ? b : *std::prev(after);
        const double k = b.t_s > a.t_s ? (seen.t_s - a.t_s) / (b.t_s - a.t_s) : 0;
        const double x = a.x_m + k * (b.x_m - a.x_m), y = a.y_m + k * (b.y_m - a.y_m);
        const double yaw = a.yaw_rad + k * std::remainder(b.yaw_rad - a.yaw_rad, 2 * M_PI);
        const double d = std::hypot(seen.x_m - x, seen.y_m - y);
        car.ips_error_m.push_back({.t_s = seen.t_s, .value = d});
        metres.push_back(d);
        degrees.push_back(std::abs(std::remainder(seen.yaw_rad - yaw, 2 * M_PI)) * 180 / M_PI);
    }
    if (metres.empty()) return;
    car.ips_error_m_p50 = percentile(metres, 0.5);
    car.ips_error_m_p99 = percentile(metres, 0.99);
    car.ips_yaw_error_deg_p99 = percentile(degrees, 0.99);
}

/// The run's bookmarks on the lab's time axis. A mark stamped on the real clock in a simulated
/// run is placed at the lab time of the car states committed with it.
std::vector<MarkFigure> marks_of(const RecordedRun& recording, uint64_t t0, bool simulated)
{
    std::vector<std::pair<uint64_t, uint64_t>> lab_at_commit;  // (commit, data) of the car states
    if (simulated) {
        for (const auto& o : recording.instances) {
            if (o.topic != topics::vehicle_state.name) continue;
            for (const auto& s : o.samples) lab_at_commit.emplace_back(s.commit_ns, s.data_ns);
        }
        std::sort(lab_at_commit.begin(), lab_at_commit.end());
    }
    std::vector<MarkFigure> marks;
    for (const auto& o : recording.instances) {
        if (o.topic != topics::bookmark.name) continue;
        for (const auto& s : o.samples) {
            if (s.value.is_null()) continue;
            uint64_t t = s.data_ns;
            if (simulated && t >= kRealClockSince) {
                auto it = std::upper_bound(lab_at_commit.begin(), lab_at_commit.end(), std::pair{s.commit_ns, UINT64_MAX});
                if (it == lab_at_commit.begin()) continue;  // before the lab's clock ran
                t = std::prev(it)->second;
            }
            marks.push_back({.t_s = seconds_since(t0, t), .text = s.value.value("text", ""), .source = s.value.value("source", "")});
        }
    }
    std::stable_sort(marks.begin(), marks.end(), [](const MarkFigure& a, const MarkFigure& b) { return a.t_s < b.t_s; });
    return marks;
}

/// Each gate of the world judged on the car's path (the path of its reference point).
void judge_gates(CarFigures& car, const vehicle::World& world)
{
    std::vector<aruco::PathPoint> path;
    for (const auto& p : car.path) path.push_back({p.t_s, {p.x_m, p.y_m, p.yaw_rad}});
    for (const auto& g : aruco::gate_passages(world, path, vehicle::VehicleParameters{}.width)) {
        car.gates_passed += g.passed;
        car.gates.push_back(g.passed ? GateFigures{.gate = g.gate + 1, .passed = true, .t_s = g.t, .offset_m = g.offset, .clearance_m = g.clearance}
                                     : GateFigures{.gate = g.gate + 1});
    }
}

/// A car's numbers, from its series.
void complete_car(CarFigures& car, const vehicle::World* world)
{
    std::sort(car.path.begin(), car.path.end(), [](const CarPose& a, const CarPose& b) { return a.t_s < b.t_s; });
    if (world && !world->walls().empty()) {
        for (const auto& p : car.path) car.clearance_m.push_back({.t_s = p.t_s, .value = world->nearest_wall(p.x_m, p.y_m)});
    }
    for (size_t i = 1; i < car.path.size(); ++i) car.driven_m += std::hypot(car.path[i].x_m - car.path[i - 1].x_m, car.path[i].y_m - car.path[i - 1].y_m);
    for (const auto& v : car.speed_m_s) car.max_speed_m_s = std::max(car.max_speed_m_s, v.value);
    double clearance_min = std::numeric_limits<double>::infinity();
    for (const auto& d : car.clearance_m) clearance_min = std::min(clearance_min, d.value);
    if (std::isfinite(clearance_min)) car.min_clearance_m = clearance_min;
    if (world && !world->gates().empty()) judge_gates(car, *world);
    if (!car.ips.empty()) judge_ips(car);
}

/// The smallest distance between two cars' reference points, every 0.1 s of the run.
std::vector<TimedValue> closest_between(const std::map<int, CarFigures>& cars)
{
    std::vector<TimedValue> closest;
    if (cars.size() < 2) return closest;
    double end = 0;
    for (const auto& [id, car] : cars) end = std::max(end, car.path.empty() ? 0.0 : car.path.back().t_s);
    for (double t = 0; t <= end; t += 0.1) {
        Line at;
        for (const auto& [id, car] : cars) {
            auto it = std::upper_bound(car.path.begin(), car.path.end(), t, [](double v, const CarPose& p) { return v < p.t_s; });
            if (it == car.path.begin()) continue;
            --it;
            at.emplace_back(it->x_m, it->y_m);
        }
        double d = std::numeric_limits<double>::infinity();
        for (size_t i = 0; i < at.size(); ++i) {
            for (size_t k = i + 1; k < at.size(); ++k) d = std::min(d, std::hypot(at[i].first - at[k].first, at[i].second - at[k].second));
        }
        if (std::isfinite(d)) closest.push_back({.t_s = t, .value = d});
    }
    return closest;
}

// ---- The figures as summary.json's "report" --------------------------------------------------

nlohmann::json json_of(const CarFigures& car, size_t gates)
{
    nlohmann::json c{{"driven_m", car.driven_m}, {"max_speed_mps", car.max_speed_m_s}, {"states_entered", car.states.size()}};
    c["min_clearance_m"] = car.min_clearance_m ? nlohmann::json(*car.min_clearance_m) : nlohmann::json(nullptr);
    if (!car.states.empty()) c["last_state"] = car.states.back().state;
    if (!car.ips.empty()) {
        c["ips_samples"] = car.ips.size();
        for (const auto& [name, v] : {std::pair{"ips_error_m_p50", car.ips_error_m_p50}, {"ips_error_m_p99", car.ips_error_m_p99},
                                      {"ips_yaw_error_deg_p99", car.ips_yaw_error_deg_p99}}) {
            c[name] = v ? nlohmann::json(*v) : nlohmann::json(nullptr);
        }
    }
    if (gates > 0) {
        nlohmann::json list = nlohmann::json::array();
        for (const auto& g : car.gates) {
            list.push_back(g.passed ? nlohmann::json{{"gate", g.gate}, {"passed", true}, {"t_s", g.t_s}, {"offset_m", g.offset_m}, {"clearance_m", g.clearance_m}}
                                    : nlohmann::json{{"gate", g.gate}, {"passed", false}});
        }
        c["gates"] = list;
        c["gates_passed"] = car.gates_passed;
    }
    return c;
}

nlohmann::json json_of(const RunFigures& f)
{
    nlohmann::json figures{{"cars", nlohmann::json::object()}, {"topics", nlohmann::json::object()}};
    for (const auto& [id, car] : f.cars) figures["cars"][std::to_string(id)] = json_of(car, f.gates_in_world);
    figures["min_distance_between_cars_m"] = f.min_distance_between_cars_m ? nlohmann::json(*f.min_distance_between_cars_m) : nlohmann::json(nullptr);
    for (const auto& [name, t] : f.topics) {
        nlohmann::json topic{{"samples", t.samples}, {"rate_hz", t.rate_hz}, {"rate_per", t.per_lab_second ? "lab second" : "real second"}};
        if (t.delay_ms_p50) topic.update({{"delay_ms_p50", *t.delay_ms_p50}, {"delay_ms_p99", t.delay_ms_p99.value_or(0.0)}});
        figures["topics"][name] = topic;
    }
    figures["missed_deadlines"] = f.missed_deadlines;
    figures["missed_deadlines_by_timer"] = f.missed_ticks_by_timer;
    figures["log_errors"] = f.log_errors;
    figures["log_warnings"] = f.log_warnings;
    figures["marks"] = nlohmann::json::array();
    for (const auto& m : f.marks) figures["marks"].push_back({{"t_s", m.t_s}, {"text", m.text}, {"source", m.source}});
    return figures;
}

// ---- The plots ---------------------------------------------------------------------------------

/// A gnuplot string literal.
std::string quoted(const std::string& s)
{
    std::string out = "\"";
    for (char c : s) out += (c == '"' || c == '\\') ? std::string("\\") + c : std::string(1, c);
    return out + "\"";
}

Line points_of(const std::vector<TimedValue>& series)
{
    Line points;
    for (const auto& v : series) points.emplace_back(v.t_s, v.value);
    return points;
}

/// One gnuplot script drawing PNG files into a folder, beside the data files it reads.
class PlotScript
{
public:
    explicit PlotScript(fs::path folder) : folder_(std::move(folder))
    {
        fs::create_directories(folder_);
        script_ << "set terminal png size 960,600 font ',11'\nset grid\nset key outside right top\n";
    }

    std::string path(const std::string& file) const { return (folder_ / file).string(); }
    std::ostream& script() { return script_; }
    std::vector<MarkFigure> marks_;

    /// Writes the data file `file`, a line "a b" per point; its path.
    std::string data(const std::string& file, const Line& points)
    {
        std::ofstream out(path(file));
        for (const auto& [a, b] : points) out << a << ' ' << b << '\n';
        return path(file);
    }

    /// The next plot goes to the image `file`.
    void image(const std::string& file)
    {
        images_.push_back(path(file));
        script_ << "set output " << quoted(path(file)) << "\n";
    }

    /// The bookmarks every plot over lab time draws: a dashed line each, with its text.
    void marks(const std::vector<MarkFigure>& marks) { marks_ = marks; }

    /// A plot over lab time of each (data file, title) of `series`; none when there are none.
    void over_time(const std::string& file, const std::string& title, const std::string& ylabel,
                   const std::vector<std::pair<std::string, std::string>>& series, const std::string& with = "lines")
    {
        if (series.empty()) return;
        image(file);
        script_ << "set title " << quoted(title) << "\nset xlabel 'lab time (s)'\nset ylabel " << quoted(ylabel) << "\nunset size\n";
        draw_marks();
        script_ << "plot ";
        for (size_t i = 0; i < series.size(); ++i) {
            script_ << (i ? ", " : "") << quoted(series[i].first) << " using 1:2 with " << with << " lw 2 title " << quoted(series[i].second);
        }
        script_ << "\nunset arrow\nunset label\n";
    }
    /// The bookmarks as dashed vertical lines labelled with their text (before a plot over lab time).
    void draw_marks()
    {
        for (const auto& m : marks_) {
            script_ << "set arrow from " << m.t_s << ", graph 0 to " << m.t_s << ", graph 1 nohead dt 2 lw 1.5 lc rgb '#b03030' front\n"
                    << "set label " << quoted(m.text) << " at " << m.t_s << ", graph 0.97 rotate by 90 right offset -0.8,0 font ',9' tc rgb '#b03030' front\n";
        }
    }

    /// Runs gnuplot on the script; the images' paths. Throws cpm::Error with gnuplot's log when it fails.
    std::vector<std::string> draw()
    {
        const std::string file = path("plots.gp"), log = path("gnuplot.log");
        std::ofstream(file) << script_.str();
        cpm::ChildProcess gnuplot({.argv = {"/usr/bin/gnuplot", file}, .stdout_path = log, .stderr_path = log});
        const auto end = gnuplot.wait(std::chrono::seconds(60));
        if (!end || !end->ok()) {
            std::ifstream in(log);
            const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
            throw Error("gnuplot failed on " + file + ": " + text);
        }
        return images_;
    }

private:
    fs::path folder_;
    std::ostringstream script_;
    std::vector<std::string> images_;
};

void write_map_layers(PlotScript& p, const RunFolder& run)
{
    std::ofstream walls(p.path("walls.dat")), markers(p.path("markers.dat")), lanes(p.path("lanes.dat"));
    if (run.world) {
        for (const auto& s : run.world->walls()) walls << s.x1 << ' ' << s.y1 << '\n' << s.x2 << ' ' << s.y2 << "\n\n";
        for (const auto& m : run.world->markers()) markers << m.x << ' ' << m.y << ' ' << m.id << '\n';
    }
    for (const auto& line : run.lanes) {
        for (const auto& [x, y] : line) lanes << x << ' ' << y << '\n';
        lanes << "\n";
    }
}

/// The cars' paths on the map: walls, markers, lanes.
void plot_map(PlotScript& p, const RunFolder& run, const RunFigures& f)
{
    write_map_layers(p, run);
    p.image("map.png");
    p.script() << "set title 'paths on the map'\nset xlabel 'x (m)'\nset ylabel 'y (m)'\nset size ratio -1\nplot ";
    std::vector<std::string> parts;
    if (!run.lanes.empty()) parts.push_back(quoted(p.path("lanes.dat")) + " using 1:2 with lines lc rgb '#cccccc' title 'lanes'");
    if (run.world && !run.world->walls().empty()) parts.push_back(quoted(p.path("walls.dat")) + " using 1:2 with lines lw 3 lc rgb 'black' title 'walls'");
    if (run.world && !run.world->markers().empty()) {
        parts.push_back(quoted(p.path("markers.dat")) + " using 1:2 with points pt 5 ps 1.2 lc rgb '#aa00aa' title 'markers'");
    }
    for (const auto& [id, car] : f.cars) {
        Line xy;
        for (const auto& pose : car.path) xy.emplace_back(pose.x_m, pose.y_m);
        parts.push_back(quoted(p.data("path_" + std::to_string(id) + ".dat", xy)) + " using 1:2 with lines lw 2 title 'car " + std::to_string(id) + "'");
    }
    if (parts.empty()) parts.push_back("0 notitle");
    for (size_t i = 0; i < parts.size(); ++i) p.script() << (i ? ", " : "") << parts[i];
    p.script() << "\nset size noratio\n";
}

/// The state machines' states over time, a step for each state entered.
void plot_states(PlotScript& p, const RunFigures& f)
{
    std::map<std::string, int> state_index;
    for (const auto& [id, car] : f.cars) {
        for (const auto& s : car.states) state_index.emplace(s.state, int(state_index.size()));
    }
    std::vector<std::pair<std::string, std::string>> states;
    for (const auto& [id, car] : f.cars) {
        if (car.states.empty()) continue;
        Line steps;
        const double end = car.path.empty() ? car.states.back().t_s : std::max(car.states.back().t_s, car.path.back().t_s);
        for (const auto& s : car.states) steps.emplace_back(s.t_s, state_index[s.state]);
        steps.emplace_back(end, state_index[car.states.back().state]);
        states.emplace_back(p.data("fsm_" + std::to_string(id) + ".dat", steps), "car " + std::to_string(id));
    }
    if (states.empty()) return;
    p.script() << "set ytics (";
    bool first = true;
    for (const auto& [name, i] : state_index) {
        p.script() << (first ? "" : ", ") << quoted(name) << " " << i;
        first = false;
    }
    p.script() << ")\nset yrange [-0.5:" << state_index.size() - 0.5 << "]\n";
    p.over_time("fsm.png", "state machine: state over time", "state", states, "steps");
    p.script() << "set ytics autofreq\nset yrange [*:*]\n";
}

/// Speed, steering, states and clearance of each car over time, the closest two cars' distance.
void plot_cars_over_time(PlotScript& p, const RunFigures& f)
{
    std::vector<std::pair<std::string, std::string>> speed, steering, clearance, ips;
    for (const auto& [id, car] : f.cars) {
        const std::string n = std::to_string(id);
        if (!car.speed_m_s.empty()) speed.emplace_back(p.data("speed_" + n + ".dat", points_of(car.speed_m_s)), "car " + n);
        if (!car.steering.empty()) steering.emplace_back(p.data("steering_" + n + ".dat", points_of(car.steering)), "car " + n);
        if (!car.clearance_m.empty()) clearance.emplace_back(p.data("clearance_" + n + ".dat", points_of(car.clearance_m)), "car " + n);
        if (!car.ips_error_m.empty()) {
            std::vector<TimedValue> mm;
            for (const auto& e : car.ips_error_m) mm.push_back({.t_s = e.t_s, .value = e.value * 1000});
            ips.emplace_back(p.data("ips_error_" + n + ".dat", points_of(mm)), "car " + n);
        }
    }
    p.over_time("speed.png", "speed", "m/s", speed);
    p.over_time("steering.png", "steering (servo command)", "-1 .. 1", steering);
    plot_states(p, f);
    p.over_time("clearance.png", "clearance to the nearest wall (reference point)", "m", clearance);
    p.over_time("ips_error.png", "positioning system (IPS) against the simulator's truth", "error (mm)", ips);
    if (!f.closest_m.empty()) {
        p.over_time("cars.png", "smallest distance between two cars (reference points)", "m", {{p.data("closest.dat", points_of(f.closest_m)), "closest pair"}});
    }
}

/// Samples per second by topic.
void plot_rates(PlotScript& p, const RunFigures& f)
{
    {
        std::ofstream out(p.path("rates.dat"));
        int i = 0;
        for (const auto& [name, t] : f.topics) out << i++ << ' ' << quoted(name) << ' ' << t.rate_hz << '\n';
    }
    p.image("topics.png");
    // A log scale: the lab clock's topics in simulated time run thousands a second beside the
    // cars' 50 Hz.
    p.script() << "set title '" << (f.simulated() ? "samples per second by topic (stamped topics per lab second, the others per real second)"
                                                  : "samples per second, by topic")
               << "'\nset xlabel ''\nset ylabel 'Hz (log scale)'\nset logscale y\nset yrange [0.1:*]\nset style fill solid 0.6\nset boxwidth 0.7\n"
                  "set xtics rotate by -40\nplot " << quoted(p.path("rates.dat")) << " using 1:3:xtic(2) with boxes notitle\n"
                  "set xtics norotate\nunset logscale y\nset yrange [*:*]\n";
}

/// Draws the plots into the folder `plots`; their paths.
std::vector<std::string> draw_plots(const fs::path& plots, const RunFolder& run, const RunFigures& f)
{
    PlotScript p(plots);
    p.marks(f.marks);
    plot_map(p, run, f);
    plot_cars_over_time(p, f);
    plot_rates(p, f);
    return p.draw();
}

// ---- The page ----------------------------------------------------------------------------------

std::string fixed(double v, int decimals)
{
    std::ostringstream s;
    s.setf(std::ios::fixed);
    s.precision(decimals);
    s << v;
    return s.str();
}

detail::PageValues car_row(int id, const CarFigures& car, size_t gates)
{
    return {.text = {{"car", std::to_string(id)},
                     {"driven_m", fixed(car.driven_m, 2)},
                     {"max_speed_m_s", fixed(car.max_speed_m_s, 2)},
                     {"min_clearance_m", car.min_clearance_m ? fixed(*car.min_clearance_m, 3) : "-"},
                     {"last_state", car.states.empty() ? "-" : car.states.back().state},
                     {"gates_passed", std::to_string(car.gates_passed)}},
            .flags = {{"all_gates_passed", car.gates_passed >= int(gates)}}};
}

detail::PageValues topic_row(const std::string& name, const TopicFigures& t)
{
    return {.text = {{"topic", name},
                     {"samples", std::to_string(t.samples)},
                     {"rate_hz", fixed(t.rate_hz, 1)},
                     {"delay_ms_p50", t.delay_ms_p50 ? fixed(*t.delay_ms_p50, 2) : "-"},
                     {"delay_ms_p99", t.delay_ms_p99 ? fixed(*t.delay_ms_p99, 2) : "-"}}};
}

detail::PageValues log_row(const LogLine& l)
{
    return {.text = {{"t_s", l.t_s ? fixed(*l.t_s, 3) : "-"}, {"level", l.error ? "error" : "warn"}, {"node", l.node}, {"text", l.text}},
            .flags = {{"error", l.error}}};
}

/// The page's lists: images, cars, topics, timers, log lines.
void fill_lists(detail::PageValues& v, const RunFigures& f, const std::vector<std::string>& images)
{
    auto& lists = v.lists;
    for (const char* key : {"images", "cars", "topics", "timers", "log", "hosts", "controllers", "marks"}) lists[key];
    for (const auto& m : f.marks) lists["marks"].push_back({.text = {{"t_s", fixed(m.t_s, 3)}, {"source", m.source}, {"text", m.text}}});
    for (const auto& file : images) lists["images"].push_back({.text = {{"file", file}}});
    // In the order summary.json's "report" lists the cars: by id as text (12 before 6).
    std::map<std::string, std::pair<int, const CarFigures*>> by_text;
    for (const auto& [id, car] : f.cars) by_text.emplace(std::to_string(id), std::pair{id, &car});
    for (const auto& [text, car] : by_text) lists["cars"].push_back(car_row(car.first, *car.second, f.gates_in_world));
    for (const auto& [name, t] : f.topics) lists["topics"].push_back(topic_row(name, t));
    for (const auto& [timer, n] : f.missed_ticks_by_timer) lists["timers"].push_back({.text = {{"timer", timer}, {"missed", std::to_string(n)}}});
    for (const auto& l : f.log) lists["log"].push_back(log_row(l));
    for (const auto& h : f.hosts) {
        lists["hosts"].push_back({.text = {{"host", h.name},
                                           {"address", h.address},
                                           {"clock_offset_ms", fixed(h.clock_offset_ms, 3)},
                                           {"rtt_ms", fixed(h.rtt_ms, 3)}},
                                  .flags = {{"lost", h.lost}}});
    }
    for (const auto& c : f.controllers) {
        lists["controllers"].push_back({.text = {{"controller", c.name},
                                                 {"vehicles", c.vehicles},
                                                 {"periods", std::to_string(c.periods)},
                                                 {"answered", std::to_string(c.answered)},
                                                 {"unanswered", std::to_string(c.unanswered)},
                                                 {"response_ms_p50", fixed(c.response_ms_p50, 2)},
                                                 {"response_ms_p99", fixed(c.response_ms_p99, 2)},
                                                 {"forwarded", std::to_string(c.forwarded)},
                                                 {"refused", std::to_string(c.refused)},
                                                 {"refusals", c.refusals}},
                                        .flags = {{"late", c.unanswered > 0}, {"refusing", c.refused > 0}}});
    }
}

}  // namespace

RunFigures figures_of(const RecordedRun& recording, const nlohmann::json& summary, const vehicle::World* world)
{
    RunFigures f = outline_of(summary);
    f.recorded_samples = recording.samples;
    f.recording_warning = recording.warning;
    const std::string loss = recording_loss(recording_lost_by_topic(summary.value("recording", nlohmann::json())));
    if (!loss.empty()) f.recording_warning += (f.recording_warning.empty() ? "" : "; ") + loss;
    f.topics = topic_figures(recording, f.simulated());
    read_samples(recording, f);
    f.marks = marks_of(recording, lab_zero_ns(recording), f.simulated());
    for (auto& [id, car] : f.cars) complete_car(car, world);
    f.gates_in_world = world ? world->gates().size() : 0;
    f.closest_m = closest_between(f.cars);
    for (const auto& c : f.closest_m) f.min_distance_between_cars_m = std::min(f.min_distance_between_cars_m.value_or(c.value), c.value);
    for (const auto& [timer, n] : f.missed_ticks_by_timer) f.missed_deadlines += n;
    for (const auto& l : f.log) ++(l.error ? f.log_errors : f.log_warnings);
    return f;
}

std::string report_page(const RunFigures& f, const std::vector<std::string>& images)
{
    detail::PageValues v{.text = {{"name", f.name},
                                  {"time", f.time},
                                  {"lab_time_s", fixed(f.lab_time_s, 1)},
                                  {"real_s", fixed(f.real_s, 1)},
                                  {"clock_real_s", fixed(f.clock_real_s, 1)},
                                  {"speedup", fixed(f.clock_real_s > 0 ? f.lab_time_s / f.clock_real_s : 0, 1)},
                                  {"why_not_ok", f.why_not_ok},
                                  {"recorded_samples", std::to_string(f.recorded_samples)},
                                  {"recording_warning", f.recording_warning},
                                  {"gates", std::to_string(f.gates_in_world)},
                                  {"missed_deadlines", std::to_string(f.missed_deadlines)},
                                  {"log_count", std::to_string(f.log.size())}},
                         .flags = {{"ok", f.ok},
                                   {"recording_warned", !f.recording_warning.empty()},
                                   {"with_gates", f.gates_in_world > 0},
                                   {"simulated", f.simulated()},
                                   {"clock_timed", f.clock_real_s > 0},
                                   {"any_missed", !f.missed_ticks_by_timer.empty()},
                                   {"any_log", !f.log.empty()},
                                   {"across_hosts", !f.hosts.empty()},
                                   {"with_controllers", !f.controllers.empty()},
                                   {"any_marks", !f.marks.empty()}}};
    fill_lists(v, f, images);
    return detail::fill(detail::kReportPage, v);
}

Report make_report(const std::string& run_dir)
{
    const fs::path dir(run_dir);
    const RunFolder run = read_run_folder(run_dir);
    const RunFigures figures = figures_of(run.recording, named(run.summary, dir.filename().string()), run.world ? &*run.world : nullptr);
    Report report{.html = (dir / "report.html").string(), .images = draw_plots(dir / "plots", run, figures), .figures = json_of(figures)};
    std::vector<std::string> files;
    for (const auto& image : report.images) files.push_back(fs::path(image).filename().string());
    std::ofstream(report.html) << report_page(figures, files);
    nlohmann::json summary = run.summary;
    summary["report"] = report.figures;
    std::ofstream(dir / "summary.json") << summary.dump(2) << "\n";
    return report;
}

}  // namespace cpm::lab
