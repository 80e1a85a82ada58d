#include <cpm/lab/Report.hpp>

#include <cpm/ChildProcess.hpp>
#include <cpm/Error.hpp>
#include <cpm/aruco/GateCourse.hpp>
#include <cpm/vehicle/VehicleModel.hpp>
#include <cpm/vehicle/World.hpp>
#include <cpm/Timer.hpp>
#include <cpm/percentile.hpp>
#include <cpm/rtdb/IdlDecoder.hpp>
#include <cpm/rtdb/Recording.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <optional>
#include <sstream>
#include <tuple>
#include <unistd.h>

namespace cpm::lab {

namespace fs = std::filesystem;

namespace {

/// A stamp at or after 2001-09-09 is on the real clock (ns since 1970); the lab's simulated
/// clock counts from 0 at the run's start.
constexpr uint64_t kRealClockSince = 1'000'000'000'000'000'000ull;

struct Point
{
    double t, x, y, yaw;
};

struct Car
{
    std::vector<Point> path;                                 ///< true pose (vehicleObservation), else its own estimate
    std::vector<std::pair<double, double>> speed, steering;  ///< t, value
    std::vector<std::pair<double, std::string>> states;      ///< t, FSM state entered
    std::vector<std::pair<double, double>> clearance;        ///< t, m to the nearest wall
};

using Segment = std::array<double, 4>;

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

std::string html_escape(const std::string& s)
{
    std::string out;
    for (char c : s) {
        if (c == '<') out += "&lt;";
        else if (c == '>') out += "&gt;";
        else if (c == '&') out += "&amp;";
        else if (c == '"') out += "&quot;";
        else out += c;
    }
    return out;
}

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

std::string fixed(double v, int decimals)
{
    std::ostringstream s;
    s.setf(std::ios::fixed);
    s.precision(decimals);
    s << v;
    return s.str();
}

/// A gnuplot string literal.
std::string quoted(const std::string& s)
{
    std::string out = "\"";
    for (char c : s) out += (c == '"' || c == '\\') ? std::string("\\") + c : std::string(1, c);
    return out + "\"";
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

}  // namespace

Report make_report(const std::string& run_dir)
{
    const fs::path dir(run_dir);
    if (!fs::is_directory(dir)) throw Error("no run folder " + run_dir);
    const std::string recording = (dir / "recording.db").string();
    if (!fs::exists(recording)) throw Error(run_dir + " holds no recording.db");
    if (::access("/usr/bin/gnuplot", X_OK) != 0) {
        throw Error("gnuplot is not installed (Debian package gnuplot-nox; ./lab installs it)");
    }
    const auto rec = load(recording);
    if (rec.samples == 0) {
        // Nothing to draw: say why instead of handing gnuplot empty data ("x range is invalid").
        throw Error(recording + " holds no samples" + (rec.warning.empty() ? "" : ": " + rec.warning));
    }
    const rtdb::IdlDecoder* types = rec.types ? rec.types.get() : rtdb::IdlDecoder::lab_types();
    if (!types) throw Error(recording + " carries no IDL and none is installed");
    nlohmann::json summary = read_json((dir / "summary.json").string());
    if (summary.is_null()) summary = nlohmann::json::object();

    // The map: walls and markers of the world, the lanes.
    std::vector<Segment> walls;
    std::vector<std::array<double, 3>> markers;  // x, y, id
    std::vector<std::vector<std::pair<double, double>>> lanes;
    std::optional<vehicle::World> world;  // read and checked once: its walls, markers and gates
    if (summary.contains("world") && summary["world"].is_string() && !summary["world"].get<std::string>().empty()) {
        try {
            world = vehicle::World::load(summary["world"]);
        } catch (const std::exception&) {
            // a world that cannot be read: the report is drawn without the map
        }
    }
    if (world) {
        for (const auto& w : world->walls()) walls.push_back({w.x1, w.y1, w.x2, w.y2});
        for (const auto& m : world->markers()) markers.push_back({m.x, m.y, double(m.id)});
    }
    if (summary.contains("lanes") && summary["lanes"].is_string()) {
        const auto graph = read_json(summary["lanes"]);
        if (graph.is_object()) {
            for (const auto& e : graph.value("edges", nlohmann::json::array())) {
                std::vector<std::pair<double, double>> line;
                for (const auto& p : e["points"]) line.emplace_back(p[0], p[1]);
                lanes.push_back(std::move(line));
            }
        }
    }

    // Every sample of the topics the plots need, by data time from the run's first one.
    std::map<int, Car> cars;
    // In simulated time the stamps are lab time and the commits the history's real clock: a
    // stamped topic's rate is per lab second there, and create -> commit means nothing.
    const bool simulated = summary.value("time", std::string()) == "simulated";
    struct TopicFigures
    {
        uint64_t samples = 0, first = std::numeric_limits<uint64_t>::max(), last = 0;
        std::vector<double> delay_ms;
        bool stamped = true;
        double rate_hz() const { return last > first ? double(samples - 1) / (double(last - first) * 1e-9) : 0.0; }
    };
    std::map<std::string, TopicFigures> topics;
    std::vector<std::tuple<double, std::string, std::string, std::string>> log_lines;  // t, level, node, text
    std::map<std::string, uint64_t> missed_by_timer;  // the nodes' timers' own counts, from the log
    uint64_t t0 = std::numeric_limits<uint64_t>::max();
    std::vector<std::pair<rtdb::ObjectInfo, std::vector<rtdb::StoredSample>>> all;
    for (const auto& o : rec.store->search({.kind = rtdb::ObjectKind::instance})) {
        auto samples = rec.store->range(o.oid, 0, UINT64_MAX, rtdb::By::commit, 100'000'000).samples;
        auto& f = topics[o.topic];
        f.stamped = o.data_time == "create_stamp";
        const bool lab_clock = simulated && f.stamped;
        for (const auto& s : samples) {
            ++f.samples;
            f.first = std::min(f.first, lab_clock ? s.data_ns : s.commit_ns);
            f.last = std::max(f.last, lab_clock ? s.data_ns : s.commit_ns);
            if (f.stamped && !simulated && s.commit_ns >= s.data_ns) f.delay_ms.push_back(double(s.commit_ns - s.data_ns) * 1e-6);
            if (o.topic == "vehicleObservation" || o.topic == "vehicleState") t0 = std::min(t0, s.data_ns);
        }
        all.emplace_back(o, std::move(samples));
    }
    if (t0 == std::numeric_limits<uint64_t>::max()) t0 = rec.started_ns;
    auto seconds = [&](uint64_t t) { return t >= t0 ? double(t - t0) * 1e-9 : -double(t0 - t) * 1e-9; };
    bool observed = false;
    for (const auto& [o, samples] : all) observed = observed || o.topic == "vehicleObservation";
    for (const auto& [o, samples] : all) {
        const bool path_topic = o.topic == (observed ? "vehicleObservation" : "vehicleState");
        if (!path_topic && o.topic != "vehicleState" && o.topic != "fsmStatus" && o.topic != "log") continue;
        for (const auto& s : samples) {
            const auto j = types->decode(o.type_name, s.payload);
            if (!j) continue;
            const double t = seconds(s.data_ns);
            if (o.topic == "log") {
                const int level = j->value("log_level", 3);
                // Simulated: a node on the lab clock stamps lab time; one on the real clock (the
                // history) cannot be placed on the lab's time axis.
                const uint64_t stamp = j->value(nlohmann::json::json_pointer("/stamp/nanoseconds"), uint64_t{0});
                const double when = !simulated ? seconds(s.commit_ns) : stamp < kRealClockSince ? seconds(stamp) : std::nan("");
                if (level <= 2) log_lines.emplace_back(when, level == 1 ? "error" : "warn", j->value("id", ""), j->value("content", ""));
                if (const auto missed = timer_missed_ticks(j->value("content", ""))) {
                    missed_by_timer[missed->first] = std::max(missed_by_timer[missed->first], missed->second);
                }
                continue;
            }
            Car& car = cars[j->value("vehicle_id", 0)];
            if (path_topic) car.path.push_back({t, j->at("pose").value("x", 0.0), j->at("pose").value("y", 0.0), j->at("pose").value("yaw", 0.0)});
            if (o.topic == "vehicleState") {
                car.speed.emplace_back(t, j->value("speed", 0.0));
                car.steering.emplace_back(t, j->value("steering_servo", 0.0));
            }
            if (o.topic == "fsmStatus") car.states.emplace_back(t, j->value("state_type", std::string("?")));
        }
    }
    for (auto& [id, car] : cars) {
        std::sort(car.path.begin(), car.path.end(), [](const Point& a, const Point& b) { return a.t < b.t; });
        if (walls.empty()) continue;
        for (const auto& p : car.path) car.clearance.emplace_back(p.t, world->nearest_wall(p.x, p.y));
    }
    // The smallest distance between two cars' reference points, every 0.1 s of the run.
    std::vector<std::pair<double, double>> closest;
    if (cars.size() >= 2) {
        double end = 0;
        for (const auto& [id, car] : cars) end = std::max(end, car.path.empty() ? 0.0 : car.path.back().t);
        for (double t = 0; t <= end; t += 0.1) {
            std::vector<std::pair<double, double>> at;
            for (const auto& [id, car] : cars) {
                auto it = std::upper_bound(car.path.begin(), car.path.end(), t, [](double v, const Point& p) { return v < p.t; });
                if (it == car.path.begin()) continue;
                --it;
                at.emplace_back(it->x, it->y);
            }
            double d = std::numeric_limits<double>::infinity();
            for (size_t i = 0; i < at.size(); ++i) {
                for (size_t k = i + 1; k < at.size(); ++k) d = std::min(d, std::hypot(at[i].first - at[k].first, at[i].second - at[k].second));
            }
            if (std::isfinite(d)) closest.emplace_back(t, d);
        }
    }

    // The data files and one gnuplot script.
    const fs::path plots = dir / "plots";
    fs::create_directories(plots);
    auto write_series = [&](const std::string& name, const std::vector<std::pair<double, double>>& v) {
        std::ofstream out(plots / name);
        for (const auto& [a, b] : v) out << a << ' ' << b << '\n';
        return (plots / name).string();
    };
    std::ostringstream gp;
    gp << "set terminal png size 960,600 font ',11'\nset grid\nset key outside right top\n";
    Report report;
    auto image = [&](const std::string& name) {
        const std::string path = (plots / name).string();
        report.images.push_back(path);
        gp << "set output " << quoted(path) << "\n";
    };
    auto series_plot = [&](const std::string& file, const std::string& title, const std::string& ylabel,
                           const std::vector<std::pair<std::string, std::string>>& data, const std::string& with = "lines") {
        if (data.empty()) return;
        image(file);
        gp << "set title " << quoted(title) << "\nset xlabel 'lab time (s)'\nset ylabel " << quoted(ylabel) << "\nunset size\nplot ";
        for (size_t i = 0; i < data.size(); ++i) gp << (i ? ", " : "") << quoted(data[i].first) << " using 1:2 with " << with << " lw 2 title " << quoted(data[i].second);
        gp << "\n";
    };

    // The map.
    {
        std::ofstream w(plots / "walls.dat");
        for (const auto& s : walls) w << s[0] << ' ' << s[1] << '\n' << s[2] << ' ' << s[3] << "\n\n";
        std::ofstream m(plots / "markers.dat");
        for (const auto& k : markers) m << k[0] << ' ' << k[1] << ' ' << int(k[2]) << '\n';
        std::ofstream l(plots / "lanes.dat");
        for (const auto& line : lanes) {
            for (const auto& [x, y] : line) l << x << ' ' << y << '\n';
            l << "\n";
        }
        image("map.png");
        gp << "set title 'paths on the map'\nset xlabel 'x (m)'\nset ylabel 'y (m)'\nset size ratio -1\nplot ";
        std::vector<std::string> parts;
        if (!lanes.empty()) parts.push_back(quoted((plots / "lanes.dat").string()) + " using 1:2 with lines lc rgb '#cccccc' title 'lanes'");
        if (!walls.empty()) parts.push_back(quoted((plots / "walls.dat").string()) + " using 1:2 with lines lw 3 lc rgb 'black' title 'walls'");
        if (!markers.empty()) parts.push_back(quoted((plots / "markers.dat").string()) + " using 1:2 with points pt 5 ps 1.2 lc rgb '#aa00aa' title 'markers'");
        for (const auto& [id, car] : cars) {
            std::vector<std::pair<double, double>> xy;
            for (const auto& p : car.path) xy.emplace_back(p.x, p.y);
            parts.push_back(quoted(write_series("path_" + std::to_string(id) + ".dat", xy)) + " using 1:2 with lines lw 2 title 'car " + std::to_string(id) + "'");
        }
        if (parts.empty()) parts.push_back("0 notitle");
        for (size_t i = 0; i < parts.size(); ++i) gp << (i ? ", " : "") << parts[i];
        gp << "\nset size noratio\n";
    }
    std::vector<std::pair<std::string, std::string>> speed, steering, clearance, states;
    std::map<std::string, int> state_index;
    for (const auto& [id, car] : cars) {
        const std::string n = std::to_string(id);
        if (!car.speed.empty()) speed.emplace_back(write_series("speed_" + n + ".dat", car.speed), "car " + n);
        if (!car.steering.empty()) steering.emplace_back(write_series("steering_" + n + ".dat", car.steering), "car " + n);
        if (!car.clearance.empty()) clearance.emplace_back(write_series("clearance_" + n + ".dat", car.clearance), "car " + n);
        for (const auto& [t, s] : car.states) state_index.emplace(s, int(state_index.size()));
    }
    for (const auto& [id, car] : cars) {
        if (car.states.empty()) continue;
        std::vector<std::pair<double, double>> steps;
        const double end = car.path.empty() ? car.states.back().first : std::max(car.states.back().first, car.path.back().t);
        for (const auto& [t, s] : car.states) steps.emplace_back(t, state_index[s]);
        steps.emplace_back(end, state_index[car.states.back().second]);
        states.emplace_back(write_series("fsm_" + std::to_string(id) + ".dat", steps), "car " + std::to_string(id));
    }
    series_plot("speed.png", "speed", "m/s", speed);
    series_plot("steering.png", "steering (servo command)", "-1 .. 1", steering);
    if (!states.empty()) {
        gp << "set ytics (";
        bool first = true;
        for (const auto& [name, i] : state_index) {
            gp << (first ? "" : ", ") << quoted(name) << " " << i;
            first = false;
        }
        gp << ")\nset yrange [-0.5:" << state_index.size() - 0.5 << "]\n";
        series_plot("fsm.png", "state machine: state over time", "state", states, "steps");
        gp << "set ytics autofreq\nset yrange [*:*]\n";
    }
    series_plot("clearance.png", "clearance to the nearest wall (reference point)", "m", clearance);
    if (!closest.empty()) series_plot("cars.png", "smallest distance between two cars (reference points)", "m", {{write_series("closest.dat", closest), "closest pair"}});
    {
        std::ofstream out(plots / "rates.dat");
        int i = 0;
        for (const auto& [name, f] : topics) out << i++ << ' ' << quoted(name) << ' ' << f.rate_hz() << '\n';
        image("topics.png");
        // A log scale: the lab clock's topics in simulated time run thousands a second beside
        // the cars' 50 Hz.
        gp << "set title '" << (simulated ? "samples per second by topic (stamped topics per lab second, the others per real second)"
                                           : "samples per second, by topic")
           << "'\nset xlabel ''\nset ylabel 'Hz (log scale)'\nset logscale y\nset yrange [0.1:*]\nset style fill solid 0.6\nset boxwidth 0.7\n"
              "set xtics rotate by -40\nplot " << quoted((plots / "rates.dat").string()) << " using 1:3:xtic(2) with boxes notitle\n"
              "set xtics norotate\nunset logscale y\nset yrange [*:*]\n";
    }
    const std::string script = (plots / "plots.gp").string();
    std::ofstream(script) << gp.str();
    cpm::ChildProcess gnuplot({.argv = {"/usr/bin/gnuplot", script}, .stdout_path = (plots / "gnuplot.log").string(),
                               .stderr_path = (plots / "gnuplot.log").string()});
    const auto end = gnuplot.wait(std::chrono::seconds(60));
    if (!end || !end->ok()) {
        std::ifstream log(plots / "gnuplot.log");
        const std::string text((std::istreambuf_iterator<char>(log)), std::istreambuf_iterator<char>());
        throw Error("gnuplot failed on " + script + ": " + text);
    }

    // The figures as numbers.
    nlohmann::json figures{{"cars", nlohmann::json::object()}, {"topics", nlohmann::json::object()}};
    for (const auto& [id, car] : cars) {
        double driven = 0, v_max = 0, clear_min = std::numeric_limits<double>::infinity();
        for (size_t i = 1; i < car.path.size(); ++i) driven += std::hypot(car.path[i].x - car.path[i - 1].x, car.path[i].y - car.path[i - 1].y);
        for (const auto& [t, v] : car.speed) v_max = std::max(v_max, v);
        for (const auto& [t, d] : car.clearance) clear_min = std::min(clear_min, d);
        nlohmann::json c{{"driven_m", driven}, {"max_speed_mps", v_max}, {"states_entered", car.states.size()}};
        c["min_clearance_m"] = std::isfinite(clear_min) ? nlohmann::json(clear_min) : nlohmann::json(nullptr);
        if (!car.states.empty()) c["last_state"] = car.states.back().second;
        if (world && !world->gates().empty()) {
            // Each gate of the world judged on the car's path (the path of its reference point).
            std::vector<aruco::PathPoint> path;
            for (const auto& p : car.path) path.push_back({p.t, {p.x, p.y, p.yaw}});
            nlohmann::json list = nlohmann::json::array();
            int passed = 0;
            for (const auto& g : aruco::gate_passages(*world, path, vehicle::VehicleParameters{}.width)) {
                passed += g.passed;
                list.push_back(g.passed ? nlohmann::json{{"gate", g.gate + 1}, {"passed", true}, {"t_s", g.t}, {"offset_m", g.offset}, {"clearance_m", g.clearance}}
                                        : nlohmann::json{{"gate", g.gate + 1}, {"passed", false}});
            }
            c["gates"] = list;
            c["gates_passed"] = passed;
        }
        figures["cars"][std::to_string(id)] = c;
    }
    double closest_min = std::numeric_limits<double>::infinity();
    for (const auto& [t, d] : closest) closest_min = std::min(closest_min, d);
    figures["min_distance_between_cars_m"] = std::isfinite(closest_min) ? nlohmann::json(closest_min) : nlohmann::json(nullptr);
    for (const auto& [name, f] : topics) {
        nlohmann::json t{{"samples", f.samples}, {"rate_hz", f.rate_hz()}, {"rate_per", simulated && f.stamped ? "lab second" : "real second"}};
        if (!f.delay_ms.empty()) t.update({{"delay_ms_p50", percentile(f.delay_ms, 0.5)}, {"delay_ms_p99", percentile(f.delay_ms, 0.99)}});
        figures["topics"][name] = t;
    }
    size_t errors = 0, warnings = 0;
    for (const auto& l : log_lines) (std::get<1>(l) == "error" ? errors : warnings)++;
    uint64_t missed = 0;
    for (const auto& [timer, n] : missed_by_timer) missed += n;
    figures["missed_deadlines"] = missed;
    figures["missed_deadlines_by_timer"] = missed_by_timer;
    figures["log_errors"] = errors;
    figures["log_warnings"] = warnings;
    report.figures = figures;

    // The page: the images beside it, nothing fetched from elsewhere; a script counts the images
    // that loaded (data-images, data-images-loaded on <body>) for a browser test to read.
    std::ostringstream h;
    const std::string name = summary.value("name", fs::path(run_dir).filename().string());
    h << "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>cpm run " << html_escape(name) << "</title>\n"
      << "<style>body{font-family:sans-serif;margin:2em;max-width:1000px}table{border-collapse:collapse}"
         "td,th{border:1px solid #ccc;padding:2px 8px;text-align:right}td:first-child,th:first-child{text-align:left}"
         ".bad{color:#b00}img{max-width:100%;border:1px solid #eee;margin:0.5em 0}</style>\n"
      << "<script>window.addEventListener('load',()=>{const i=[...document.images];document.body.dataset.images=i.length;"
         "document.body.dataset.imagesLoaded=i.filter(x=>x.complete&&x.naturalWidth>0).length;});</script></head>\n<body>\n"
      << "<h1>Run " << html_escape(name) << "</h1>\n<p>" << html_escape(summary.value("time", std::string("?"))) << " time, "
      << fixed(summary.value("lab_time_s", 0.0), 1) << " s of lab time in " << fixed(summary.value("real_s", 0.0), 1) << " s; "
      << (summary.value("ok", false) ? "every process ran its time" : "<span class=\"bad\">the run did not end well: " + html_escape(why_not_ok(summary)) + "</span>")
      << ". Recording: <code>recording.db</code> (" << rec.samples << " samples; ask it with <code>cpm history --file recording.db</code>)"
      << (rec.warning.empty() ? std::string() : "; <span class=\"bad\">" + html_escape(rec.warning) + "</span>") << ".</p>\n";
    const bool with_gates = world && !world->gates().empty();
    h << "<h2>Cars</h2>\n<table><tr><th>car</th><th>driven (m)</th><th>top speed (m/s)</th><th>least clearance to a wall (m)</th><th>last state</th>"
      << (with_gates ? "<th>gates passed</th>" : "") << "</tr>\n";
    for (const auto& [id, c] : figures["cars"].items()) {
        h << "<tr><td>" << id << "</td><td>" << fixed(c["driven_m"], 2) << "</td><td>" << fixed(c["max_speed_mps"], 2) << "</td><td>"
          << (c["min_clearance_m"].is_null() ? "-" : fixed(c["min_clearance_m"], 3)) << "</td><td>"
          << html_escape(c.value("last_state", std::string("-"))) << "</td>";
        if (with_gates) {
            const int passed = c.value("gates_passed", 0);
            h << "<td" << (passed < int(world->gates().size()) ? " class=\"bad\"" : "") << ">" << passed << " of " << world->gates().size() << "</td>";
        }
        h << "</tr>\n";
    }
    h << "</table>\n";
    for (const auto& img : report.images) {
        const std::string file = fs::path(img).filename().string();
        h << "<div><img src=\"plots/" << file << "\" alt=\"" << file << "\"></div>\n";
    }
    h << "<h2>Topics</h2>\n";
    if (simulated) h << "<p>Simulated time: rates of stamped topics per second of lab time; their delay create → commit is not measured (two clocks).</p>\n";
    h << "<table><tr><th>topic</th><th>samples</th><th>rate (Hz)</th><th>delay create → commit p50 (ms)</th><th>p99 (ms)</th></tr>\n";
    for (const auto& [t, f] : figures["topics"].items()) {
        h << "<tr><td>" << html_escape(t) << "</td><td>" << f["samples"] << "</td><td>" << fixed(f["rate_hz"], 1) << "</td><td>"
          << (f.contains("delay_ms_p50") ? fixed(f["delay_ms_p50"], 2) : "-") << "</td><td>"
          << (f.contains("delay_ms_p99") ? fixed(f["delay_ms_p99"], 2) : "-") << "</td></tr>\n";
    }
    h << "</table>\n<h2>Missed deadlines (" << missed << ")</h2>\n<p>Ticks the nodes' timers skipped because a tick ended after the next "
         "one was due, as the timers said in the log.</p>\n";
    if (!missed_by_timer.empty()) {
        h << "<table><tr><th>timer</th><th>ticks missed</th></tr>\n";
        for (const auto& [timer, n] : missed_by_timer) h << "<tr><td>" << html_escape(timer) << "</td><td>" << n << "</td></tr>\n";
        h << "</table>\n";
    }
    h << "<h2>Warnings and errors (" << log_lines.size() << ")</h2>\n";
    if (log_lines.empty()) h << "<p>None.</p>\n";
    else {
        h << "<table><tr><th>time (s)</th><th>level</th><th>node</th><th>message</th></tr>\n";
        for (const auto& [t, level, node, text] : log_lines) {
            h << "<tr><td>" << (std::isfinite(t) ? fixed(t, 3) : "-") << "</td><td" << (level == "error" ? " class=\"bad\"" : "") << ">" << level << "</td><td>"
              << html_escape(node) << "</td><td style=\"text-align:left\">" << html_escape(text) << "</td></tr>\n";
        }
        h << "</table>\n";
    }
    h << "</body></html>\n";
    report.html = (dir / "report.html").string();
    std::ofstream(report.html) << h.str();
    summary["report"] = figures;
    std::ofstream(dir / "summary.json") << summary.dump(2) << "\n";
    return report;
}

}  // namespace cpm::lab
