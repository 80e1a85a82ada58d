// A run's figures computed from recordings built here by hand (no file, no gnuplot), each
// expected figure worked out in the test from the poses and times it puts in; and the page those
// figures are shown on, with hostile names in it.
#include <cpm/Error.hpp>
#include <cpm/lab/Report.hpp>
#include <cpm/lab/Run.hpp>
#include <cpm/vehicle/World.hpp>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <string>

using namespace cpm;
using namespace cpm::lab;
using nlohmann::json;

namespace {

constexpr uint64_t kSecond = 1'000'000'000;
constexpr uint64_t kMillisecond = 1'000'000;
/// A real-clock time (ns since 1970) for runs in real time: 2023-11-14.
constexpr uint64_t kRealStart = 1'700'000'000 * kSecond;

json observation(int car, double x, double y)
{
    return {{"vehicle_id", car}, {"pose", {{"x", x}, {"y", y}, {"yaw", 0.0}}}};
}

json state(int car, double x, double speed_m_s)
{
    return {{"vehicle_id", car}, {"pose", {{"x", x}, {"y", 0.0}, {"yaw", 0.0}}}, {"speed", speed_m_s}, {"steering_servo", 0.0}};
}

json log_message(int level, const std::string& node, const std::string& text, uint64_t stamp_ns)
{
    return {{"log_level", level}, {"id", node}, {"content", text}, {"stamp", {{"nanoseconds", stamp_ns}}}};
}

/// A sample written at `data_ns` and committed 2 ms later.
RecordedSample at(uint64_t data_ns, json value)
{
    return {.data_ns = data_ns, .commit_ns = data_ns + 2 * kMillisecond, .value = std::move(value)};
}

}  // namespace

TEST(ReportFigures, TwoCarsOneLosingSamplesAreMeasuredOnWhatWasRecorded)
{
    // Car 5 drives along y = 0 at 1 m/s, a pose each second; car 9 drives back along y = 2 and
    // only its first and last poses reached the history (t = 1 s and 2 s were lost).
    RecordedRun recording{.instances = {{.topic = "vehicleObservation",
                                         .samples = {at(kRealStart, observation(5, 0, 0)), at(kRealStart + 1 * kSecond, observation(5, 1, 0)),
                                                     at(kRealStart + 2 * kSecond, observation(5, 2, 0)), at(kRealStart + 3 * kSecond, observation(5, 3, 0))}},
                                        {.topic = "vehicleObservation",
                                         .samples = {at(kRealStart, observation(9, 3, 2)), at(kRealStart + 3 * kSecond, observation(9, 0, 2))}},
                                        {.topic = "vehicleState",
                                         .samples = {at(kRealStart, state(5, 0, 0.5)), at(kRealStart + kSecond, state(5, 1, 1.25)),
                                                     at(kRealStart + 2 * kSecond, state(5, 2, 0.75))}}},
                          .samples = 9};

    const RunFigures figures = figures_of(recording, {{"name", "two"}, {"time", "real"}, {"ok", true}});

    ASSERT_EQ(figures.cars.size(), 2u);
    const CarFigures& five = figures.cars.at(5);
    const CarFigures& nine = figures.cars.at(9);
    EXPECT_DOUBLE_EQ(five.driven_m, 3.0);
    EXPECT_DOUBLE_EQ(nine.driven_m, 3.0) << "the straight line between the two poses recorded";
    EXPECT_DOUBLE_EQ(five.max_speed_m_s, 1.25);
    EXPECT_DOUBLE_EQ(nine.max_speed_m_s, 0.0) << "car 9 sent no vehicleState";
    ASSERT_EQ(five.path.size(), 4u);
    EXPECT_DOUBLE_EQ(five.path[3].t_s, 3.0) << "seconds from the first car sample";
    EXPECT_EQ(nine.path.size(), 2u);
    EXPECT_FALSE(five.min_clearance_m.has_value()) << "no world, no walls";
    // Car 9 stays at (3, 2) until its next pose at 3 s; car 5 reaches (2, 0) at 2 s: sqrt(1 + 4).
    ASSERT_TRUE(figures.min_distance_between_cars_m.has_value());
    EXPECT_NEAR(*figures.min_distance_between_cars_m, std::sqrt(5.0), 1e-12);
    EXPECT_NEAR(figures.closest_m.front().value, std::sqrt(13.0), 1e-12) << "(0, 0) to (3, 2) at 0 s";
    // Six observations committed over 3 s of the history's clock, each 2 ms after its stamp.
    const TopicFigures& observations = figures.topics.at("vehicleObservation");
    EXPECT_EQ(observations.samples, 6u);
    EXPECT_NEAR(observations.rate_hz, 5.0 / 3.0, 1e-9);
    EXPECT_FALSE(observations.per_lab_second);
    ASSERT_TRUE(observations.delay_ms_p50.has_value());
    EXPECT_NEAR(*observations.delay_ms_p50, 2.0, 1e-9);
    EXPECT_NEAR(*observations.delay_ms_p99, 2.0, 1e-9);
    EXPECT_EQ(figures.topics.at("vehicleState").samples, 3u);
    EXPECT_TRUE(figures.ok);
    EXPECT_EQ(figures.why_not_ok, "");
    EXPECT_EQ(figures.recorded_samples, 9u);
}

TEST(ReportFigures, APathIsInDataTimeOrderNotCommitOrder)
{
    // The pose of 2 s committed before the one of 1 s: 0 -> 2 -> 1 -> 3 would be 5 m.
    RecordedRun recording{.instances = {{.topic = "vehicleObservation",
                                         .samples = {at(kRealStart, observation(1, 0, 0)), at(kRealStart + 2 * kSecond, observation(1, 2, 0)),
                                                     at(kRealStart + 1 * kSecond, observation(1, 1, 0)), at(kRealStart + 3 * kSecond, observation(1, 3, 0))}}}};

    const RunFigures figures = figures_of(recording, {{"time", "real"}});

    EXPECT_DOUBLE_EQ(figures.cars.at(1).driven_m, 3.0);
    EXPECT_DOUBLE_EQ(figures.cars.at(1).path[1].x_m, 1.0);
    EXPECT_FALSE(figures.min_distance_between_cars_m.has_value()) << "one car has no distance to another";
}

TEST(ReportFigures, ARunStoppedByRequestSaysSoAndCountsRatesPerLabSecond)
{
    // Simulated: the cars stamp lab time from 0, the history commits on its real clock, 1 ms of
    // it for each 20 ms of lab time (the run went 20 times as fast as real time).
    const uint64_t commit0 = 1'000'000'000 * kSecond;
    auto committed = [&](uint64_t data_ns, uint64_t commit_ms, json value) {
        return RecordedSample{.data_ns = data_ns, .commit_ns = commit0 + commit_ms * kMillisecond, .value = std::move(value)};
    };
    RecordedInstance states{.topic = "vehicleState"};
    for (uint64_t k = 0; k <= 50; ++k) states.samples.push_back(committed(k * 20 * kMillisecond, k, state(5, 0.01 * double(k), 0.5)));
    RecordedInstance fsm{.topic = "fsmStatus",
                         .samples = {committed(0, 0, {{"vehicle_id", 5}, {"state_type", "drive"}}),
                                     committed(600 * kMillisecond, 30, {{"vehicle_id", 5}, {"state_type", "stop"}})}};
    // The log's data time is the writer's (not stamped): its rate is per real second. Its first
    // line is stamped with lab time, the second with the real clock (as the history stamps).
    RecordedInstance log{.topic = "log",
                         .stamped = false,
                         .samples = {committed(commit0, 0, log_message(1, "fsm_5", "lost its car", 500 * kMillisecond)),
                                     committed(commit0, 250, log_message(2, "cpm_history", "slow disk", commit0)),
                                     committed(commit0, 300, log_message(3, "fsm_5", "timer 'fsm_5': overran; 4 ticks missed in all", 0)),
                                     committed(commit0, 400, log_message(3, "fsm_5", "timer 'fsm_5': stopped; 7 ticks missed in all", 0)),
                                     committed(commit0, 500, log_message(2, "bridge_5", "timer 'bridge_5': stopped; 2 ticks missed in all", 0))}};
    const json summary{{"name", "stopped"}, {"time", "simulated"}, {"ok", false}, {"interrupted", true}, {"lab_time_s", 1.0}, {"real_s", 0.05}};

    const RunFigures figures = figures_of({.instances = {states, fsm, log}}, summary);

    EXPECT_FALSE(figures.ok);
    EXPECT_EQ(figures.why_not_ok, "it was stopped (Ctrl-C or SIGTERM) before its end");
    EXPECT_TRUE(figures.simulated());
    const TopicFigures& rate = figures.topics.at("vehicleState");
    EXPECT_TRUE(rate.per_lab_second);
    EXPECT_NEAR(rate.rate_hz, 50.0, 1e-9) << "50 intervals over 1 s of lab time, not 50 ms of the history's clock";
    EXPECT_FALSE(rate.delay_ms_p50.has_value()) << "lab stamps against real commits: no delay";
    EXPECT_FALSE(figures.topics.at("log").per_lab_second);
    EXPECT_NEAR(figures.topics.at("log").rate_hz, 4 / 0.5, 1e-9) << "5 lines over 0.5 s of commits";
    // The warnings and errors, placed on the lab's time axis when stamped with lab time.
    ASSERT_EQ(figures.log.size(), 3u);
    EXPECT_TRUE(figures.log[0].error);
    EXPECT_EQ(figures.log[0].node, "fsm_5");
    ASSERT_TRUE(figures.log[0].t_s.has_value());
    EXPECT_NEAR(*figures.log[0].t_s, 0.5, 1e-12);
    EXPECT_FALSE(figures.log[1].t_s.has_value()) << "stamped on the history's real clock";
    EXPECT_EQ(figures.log_errors, 1u);
    EXPECT_EQ(figures.log_warnings, 2u);
    // Each timer's highest count, summed.
    EXPECT_EQ(figures.missed_ticks_by_timer, (std::map<std::string, uint64_t>{{"bridge_5", 2}, {"fsm_5", 7}}));
    EXPECT_EQ(figures.missed_deadlines, 9u);
    // The car's path is its own estimate (nothing observed it), its states as entered.
    EXPECT_NEAR(figures.cars.at(5).driven_m, 0.5, 1e-9);
    ASSERT_EQ(figures.cars.at(5).states.size(), 2u);
    EXPECT_EQ(figures.cars.at(5).states.back().state, "stop");
    EXPECT_NEAR(figures.cars.at(5).states.back().t_s, 0.6, 1e-12);
}

TEST(ReportFigures, AnEmptyRecordingHasNoCarsAndATopicWithoutSamplesHasNoRate)
{
    const RunFigures figures = figures_of({.instances = {{.topic = "vehicleState"}}, .warning = "not closed"}, json::object());

    EXPECT_TRUE(figures.cars.empty());
    EXPECT_TRUE(figures.closest_m.empty());
    EXPECT_FALSE(figures.min_distance_between_cars_m.has_value());
    ASSERT_EQ(figures.topics.size(), 1u);
    EXPECT_EQ(figures.topics.at("vehicleState").samples, 0u);
    EXPECT_EQ(figures.topics.at("vehicleState").rate_hz, 0.0);
    EXPECT_TRUE(figures.log.empty());
    EXPECT_EQ(figures.missed_deadlines, 0u);
    EXPECT_EQ(figures.recording_warning, "not closed");
    // A summary that says nothing: not ok, for no reason it knows.
    EXPECT_EQ(figures.time, "?");
    EXPECT_FALSE(figures.ok);
    EXPECT_EQ(figures.why_not_ok, "see summary.json");
}

TEST(ReportFigures, ASampleThatDidNotDecodeCountsInItsTopicButDrawsNothing)
{
    RecordedRun recording{.instances = {{.topic = "vehicleState",
                                         .samples = {at(kRealStart, state(4, 0, 0.2)), at(kRealStart + kSecond, nullptr),
                                                     at(kRealStart + 2 * kSecond, state(4, 1.5, 0.4))}}}};

    const RunFigures figures = figures_of(recording, {{"time", "real"}});

    EXPECT_EQ(figures.topics.at("vehicleState").samples, 3u);
    EXPECT_EQ(figures.cars.at(4).path.size(), 2u);
    EXPECT_DOUBLE_EQ(figures.cars.at(4).driven_m, 1.5);
}

TEST(ReportFigures, GatesAreJudgedOnEachCarsPathAndWallsGiveItsClearance)
{
    // Gate 1 at x = 2 between markers 0.5 m either side of y = 0, gate 2 at x = 6; a wall along
    // y = -1. Car 1 drives x = t along y = 0.1 to x = 4 (through gate 1 only), car 2 along y = 3.
    const vehicle::World world({{.x1 = 0, .y1 = -1, .x2 = 8, .y2 = -1}},
                               {{.id = 1, .x = 2, .y = 0.5}, {.id = 2, .x = 2, .y = -0.5}, {.id = 3, .x = 6, .y = 0.5}, {.id = 4, .x = 6, .y = -0.5}},
                               {{.left = 1, .right = 2}, {.left = 3, .right = 4}});
    RecordedInstance one{.topic = "vehicleObservation"}, two{.topic = "vehicleObservation"};
    for (uint64_t t = 0; t <= 4; ++t) {
        one.samples.push_back(at(kRealStart + t * kSecond, observation(1, double(t), 0.1)));
        two.samples.push_back(at(kRealStart + t * kSecond, observation(2, double(t), 3.0)));
    }

    const RunFigures figures = figures_of({.instances = {one, two}}, {{"time", "real"}}, &world);

    EXPECT_EQ(figures.gates_in_world, 2u);
    const CarFigures& car1 = figures.cars.at(1);
    EXPECT_EQ(car1.gates_passed, 1);
    ASSERT_EQ(car1.gates.size(), 2u);
    EXPECT_EQ(car1.gates[0].gate, 1);
    EXPECT_TRUE(car1.gates[0].passed);
    EXPECT_NEAR(car1.gates[0].t_s, 2.0, 1e-9);
    EXPECT_NEAR(car1.gates[0].offset_m, 0.1, 1e-9) << "0.1 m left of the centre";
    // Markers 0.1 m wide, a car 0.2 m wide: 0.5 - 0.05 - 0.1 - 0.1.
    EXPECT_NEAR(car1.gates[0].clearance_m, 0.25, 1e-9);
    EXPECT_EQ(car1.gates[1].gate, 2);
    EXPECT_FALSE(car1.gates[1].passed);
    EXPECT_EQ(figures.cars.at(2).gates_passed, 0);
    ASSERT_TRUE(car1.min_clearance_m.has_value());
    EXPECT_NEAR(*car1.min_clearance_m, 1.1, 1e-9);
    EXPECT_NEAR(*figures.cars.at(2).min_clearance_m, 4.0, 1e-9);
    EXPECT_EQ(car1.clearance_m.size(), 5u) << "one per pose";
}

TEST(ReportFigures, BookmarksArePlacedOnTheLabsTimeAxisInRealAndInSimulatedTime)
{
    auto mark = [](const std::string& text, const std::string& source) { return json{{"text", text}, {"source", source}}; };
    // Real time: the mark's stamp is on the cars' clock.
    RecordedRun real{.instances = {{.topic = "vehicleState", .samples = {at(kRealStart, state(5, 0, 0)), at(kRealStart + 4 * kSecond, state(5, 2, 0))}},
                                   {.topic = "bookmark", .samples = {at(kRealStart + 3 * kSecond, mark("late one", "b"))}},
                                   {.topic = "bookmark", .samples = {at(kRealStart + 1500 * kMillisecond, mark("first", "cpm lab mark"))}}},
                     .samples = 4};
    const auto r = figures_of(real, {{"name", "real"}, {"time", "real"}});
    ASSERT_EQ(r.marks.size(), 2u);
    EXPECT_EQ(r.marks[0].text, "first") << "in time order, whichever marking process wrote it";
    EXPECT_EQ(r.marks[0].source, "cpm lab mark");
    EXPECT_DOUBLE_EQ(r.marks[0].t_s, 1.5);
    EXPECT_DOUBLE_EQ(r.marks[1].t_s, 3.0);
    // Simulated: the cars stamp lab time (20 ms of it per real ms); a mark stamped on the real
    // clock goes where the car states committed with it are.
    const uint64_t commit0 = 1'000'000'000 * kSecond;
    RecordedInstance states{.topic = "vehicleState"};
    for (uint64_t k = 0; k <= 50; ++k) {
        states.samples.push_back({.data_ns = k * 20 * kMillisecond, .commit_ns = commit0 + k * kMillisecond, .value = state(5, 0, 0.5)});
    }
    RecordedRun simulated{.instances = {states,
                                        {.topic = "bookmark",
                                         .samples = {{.data_ns = commit0 + 10 * kMillisecond + 300'000, .commit_ns = commit0 + 10 * kMillisecond + 400'000,
                                                      .value = mark("mid", "m")},
                                                     {.data_ns = commit0, .commit_ns = commit0 - kSecond, .value = mark("before", "m")}}}},
                          .samples = 53};
    const auto s = figures_of(simulated, {{"name", "sim"}, {"time", "simulated"}});
    ASSERT_EQ(s.marks.size(), 1u) << "a mark before the lab's clock ran has no place on its axis";
    EXPECT_NEAR(s.marks[0].t_s, 0.2, 1e-9) << "the lab time of the state committed just before it";
}

TEST(ReportPage, NamesFromTheRunAreShownAsTextNeverAsMarkup)
{
    RunFigures figures;
    figures.name = "<script>alert('name')</script>";
    figures.why_not_ok = "fsm_<b>5</b> exited";
    figures.cars[5].states.push_back({.t_s = 1, .state = "<img src=x onerror=\"alert(1)\">"});
    figures.topics["a&b"] = {.samples = 2};
    figures.missed_ticks_by_timer["<timer>"] = 3;
    figures.log.push_back({.t_s = 0.5, .error = true, .node = "<node>", .text = "</td></tr></table><script>alert(2)</script>"});
    figures.marks.push_back({.t_s = 0.7, .text = "<script>alert(3)</script>", .source = "<i>me</i>"});

    const std::string page = report_page(figures, {"map.png"});

    EXPECT_EQ(page.find("<script>alert"), std::string::npos) << page;
    EXPECT_EQ(page.find("<b>5"), std::string::npos);
    EXPECT_EQ(page.find("<img src=x"), std::string::npos);
    EXPECT_NE(page.find("<title>cpm run &lt;script&gt;alert('name')&lt;/script&gt;</title>"), std::string::npos);
    EXPECT_NE(page.find("the run did not end well: fsm_&lt;b&gt;5&lt;/b&gt; exited"), std::string::npos);
    EXPECT_NE(page.find("<td>&lt;img src=x onerror=&quot;alert(1)&quot;&gt;</td>"), std::string::npos) << "the car's last state";
    EXPECT_NE(page.find("<td>a&amp;b</td>"), std::string::npos);
    EXPECT_NE(page.find("<td>&lt;timer&gt;</td><td>3</td>"), std::string::npos);
    EXPECT_NE(page.find("&lt;/td&gt;&lt;/tr&gt;&lt;/table&gt;&lt;script&gt;alert(2)"), std::string::npos);
    EXPECT_NE(page.find("<td>0.700</td><td>&lt;i&gt;me&lt;/i&gt;</td><td style=\"text-align:left\">&lt;script&gt;alert(3)&lt;/script&gt;</td>"),
              std::string::npos)
        << "a bookmark's text and source";
}

TEST(ReportPage, ShowsTheOutcomeEachCarsGatesAndNoneForAQuietLog)
{
    RunFigures figures;
    figures.name = "gates";
    figures.time = "simulated";
    figures.ok = true;
    figures.gates_in_world = 2;
    figures.cars[6].gates_passed = 2;
    figures.cars[7].gates_passed = 1;
    figures.cars[7].driven_m = 12.3456;
    figures.cars[7].min_clearance_m = 0.0627;

    const std::string page = report_page(figures, {"map.png", "speed.png"});

    EXPECT_EQ(page.find("{{"), std::string::npos) << "every tag of the template filled";
    EXPECT_NE(page.find("every process ran its time"), std::string::npos);
    EXPECT_EQ(page.find("did not end well"), std::string::npos);
    EXPECT_NE(page.find("<th>gates passed</th>"), std::string::npos);
    EXPECT_NE(page.find("<tr><td>6</td><td>0.00</td><td>0.00</td><td>-</td><td>-</td><td>2 of 2</td></tr>"), std::string::npos) << page;
    EXPECT_NE(page.find("<tr><td>7</td><td>12.35</td><td>0.00</td><td>0.063</td><td>-</td><td class=\"bad\">1 of 2</td></tr>"), std::string::npos);
    EXPECT_NE(page.find("<div><img src=\"plots/speed.png\" alt=\"speed.png\"></div>"), std::string::npos);
    EXPECT_NE(page.find("<p>Simulated time:"), std::string::npos);
    EXPECT_NE(page.find("<h2>Warnings and errors (0)</h2>\n<p>None.</p>\n</body></html>\n"), std::string::npos);
    EXPECT_EQ(page.find("<th>ticks missed</th>"), std::string::npos) << "no timer missed a tick";
}

TEST(ReportPage, AWorldWithoutGatesHasNoGatesColumn)
{
    RunFigures figures;
    figures.cars[3].driven_m = 1;

    const std::string page = report_page(figures, {});

    EXPECT_EQ(page.find("gates passed"), std::string::npos);
    EXPECT_NE(page.find("<tr><td>3</td><td>1.00</td><td>0.00</td><td>-</td><td>-</td></tr>"), std::string::npos) << page;
    EXPECT_EQ(page.find("<img"), std::string::npos);
}

TEST(ReportPage, ARunAcrossHostsShowsEachHostItsClockOffsetAndALostOne)
{
    const json summary = json::parse(R"({"name": "across", "ok": false, "hosts": [
        {"name": "central", "address": "10.0.0.1", "clock_offset_ns": 0, "rtt_ns": 0, "lost": false},
        {"name": "car<b>", "address": "10.0.0.3", "clock_offset_ns": -1234567, "rtt_ns": 800000, "lost": true}]})");
    const RunFigures figures = figures_of({}, summary);

    ASSERT_EQ(figures.hosts.size(), 2u);
    EXPECT_DOUBLE_EQ(figures.hosts[1].clock_offset_ms, -1.234567);
    EXPECT_DOUBLE_EQ(figures.hosts[1].rtt_ms, 0.8);
    EXPECT_TRUE(figures.hosts[1].lost);
    const std::string page = report_page(figures, {});
    EXPECT_NE(page.find("<h2>Hosts</h2>"), std::string::npos) << page;
    EXPECT_NE(page.find("<tr><td>central</td><td>10.0.0.1</td><td>0.000</td><td>0.000</td><td>answered</td></tr>"), std::string::npos) << page;
    EXPECT_NE(page.find("<tr><td>car&lt;b&gt;</td><td>10.0.0.3</td><td>-1.235</td><td>0.800</td><td class=\"bad\">lost</td></tr>"),
              std::string::npos)
        << page;
    // One host: no hosts table.
    EXPECT_EQ(report_page(figures_of({}, json::parse(R"({"name": "here"})")), {}).find("<h2>Hosts</h2>"), std::string::npos);
}

TEST(MakeReport, AFolderThatIsNotThereIsACpmErrorNamingIt)
{
    try {
        (void)make_report("/nonexistent/run-folder");
        FAIL() << "no error";
    } catch (const cpm::Error& e) {
        EXPECT_EQ(std::string(e.what()), "no run folder /nonexistent/run-folder");
    }
}

// What a recording missed, from summary.json's recording block, as the run and its report say it.
TEST(ReportFigures, ARecordingsLossesAreSaidPerTopicAndNothingWhenNoneWasLost)
{
    const auto lost = recording_lost_by_topic(json::parse(R"({"written": 10, "lost": 5, "lost_by_topic": {"systemTrigger": 2, "readyStatus": 3}})"));
    EXPECT_EQ(recording_loss(lost), "5 samples never reached the recorder (readyStatus 3, systemTrigger 2; it could not keep up)");
    EXPECT_EQ(recording_loss(recording_lost_by_topic(json::parse(R"({"written": 10, "lost": 0, "lost_by_topic": {}})"))), "");
    EXPECT_EQ(recording_loss(recording_lost_by_topic(json())), "") << "a run without a recording block";
}
