// fsm_node as a real process driving a simulated car (cpm vehicle sim: firmware_sim +
// vehicle_bridge over a pty) through the shipped corridor with the shipped machine.
#include <cpm/Participant.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/vehicle/VehicleModel.hpp>

#include <cpm_test/Dds.hpp>
#include <cpm_test/Isolation.hpp>
#include <cpm_test/Process.hpp>
#include <cpm_test/SourceDir.hpp>

#include <FsmStatus.h>
#include <VehicleCommandDirect.h>
#include <VehicleObservation.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <csignal>
#include <fstream>
#include <sstream>

using namespace std::chrono_literals;
using cpm_test::built_program;
using cpm_test::Process;

namespace {

/// One run of a shipped machine on simulated car 5 starting at (0, -0.01, 0) in the corridor,
/// where its right ranger is 0.5 m from the right wall: the true track, fsm_node's commands and
/// its states, until fsm_node ends in its final state.
/// The simulated car's rangers (VehicleParameters: the right one 0.20 m ahead of the rear axle, 0.09 m right).
const cpm::vehicle::UltrasonicMount kRight = cpm::vehicle::VehicleParameters{}.ultrasonic[2];
const cpm::vehicle::UltrasonicMount kFront = cpm::vehicle::VehicleParameters{}.ultrasonic[0];

struct Drive
{
    std::vector<VehicleObservation> track;
    std::vector<VehicleCommandDirect> commands;
    std::vector<int> states;
    std::vector<FsmStatus> statuses;
    std::string output;

    /// Ground truth: the right ranger's distance to the first leg's right wall (y = -0.6), from
    /// where the simulated car carries it.
    static double clearance(const VehicleObservation& o)
    {
        const auto& r = kRight;
        return o.pose().y() + r.x * std::sin(o.pose().yaw()) + r.y * std::cos(o.pose().yaw()) + 0.6;
    }
    /// The car's true x when the command was written (the observation nearest in time).
    double x_at(const VehicleCommandDirect& c) const
    {
        const uint64_t t = c.header().create_stamp().nanoseconds();
        auto it = std::lower_bound(track.begin(), track.end(), t, [](const VehicleObservation& o, uint64_t v) {
            return o.header().create_stamp().nanoseconds() < v;
        });
        return (it == track.end() ? track.back() : *it).pose().x();
    }
    /// The state fsm_node was in at data time t (its status messages' entered_ns).
    int state_at(uint64_t t) const
    {
        int state = -1;
        for (auto& s : statuses)
            if (s.entered_ns() <= t) state = s.state_id();
        return state;
    }
    /// Where the car went, every `step` metres of x: for a failure message, so that a run that
    /// went wrong says where and in which state.
    std::string profile(double step = 0.25) const
    {
        std::ostringstream out;
        out.precision(3);
        double next = -1e9;
        for (auto& o : track) {
            if (o.pose().x() < next && &o != &track.back()) continue;
            next = o.pose().x() + step;
            out << "x " << o.pose().x() << " y " << o.pose().y() << " yaw " << o.pose().yaw() << " clearance "
                << clearance(o) << " state " << state_at(o.header().create_stamp().nanoseconds()) << "\n";
        }
        return out.str();
    }
};

/// `tick`: fsm_node's --tick (timer, on-sample), or "avr": on the timer, the car's
/// microcontroller the real AVR firmware under firmware_hil instead of firmware_sim.
Drive drive(const std::string& machine, std::string tick = "timer")
{
    const bool avr = tick == "avr";
    if (avr) tick = "timer";
    cpm::Participant participant(cpm_test::isolated_options());
    cpm::ReaderAbstract<VehicleObservation> observations(participant, "vehicleObservation", {.keep_all = true});
    cpm::ReaderAbstract<VehicleCommandDirect> commands(participant, "vehicleCommandDirect", {.keep_all = true});
    // Transient-local: the status of state 0 may be published before this reader is matched.
    cpm::ReaderAbstract<FsmStatus> status(participant, "fsmStatus", {.reliable = true, .keep_all = true, .transient_local = true});
    const std::string root = cpm_test::source_dir();
    Process car({built_program("cpm"), "vehicle", "sim", "--id", "5", "--map", root + "/scenarios/maps/corridor.json",
                 "--start", "0,-0.01,0", "--firmware", avr ? "avr" : "sim"});
    Process sut({built_program("fsm_node"), "--vehicle_id", "5", "--fsm", root + "/scenarios/fsm/" + machine, "--report", "--tick", tick});
    Drive run;
    auto collect = [&] {
        for (auto& o : observations.take()) run.track.push_back(o);
        for (auto& c : commands.take()) run.commands.push_back(c);
        for (auto& s : status.take()) {
            run.states.push_back(s.state_id());
            run.statuses.push_back(s);
        }
    };
    const bool stopped = cpm_test::wait_until([&] {
        collect();
        return sut.wait(0ms) == 0;
    }, 60s, 20ms);
    EXPECT_TRUE(stopped) << sut.output() << sut.errors();
    std::this_thread::sleep_for(1s);  // the car comes to rest
    collect();
    run.output = sut.output();
    car.kill(SIGINT);
    EXPECT_EQ(car.wait(10s), 0);
    return run;
}

}  // namespace

/// The same drive with the machine ticked by the timer (the default) and on each new sample.
class FsmNodeTicking : public ::testing::TestWithParam<std::string>
{
};

INSTANTIATE_TEST_SUITE_P(FsmNodeEndToEnd, FsmNodeTicking, ::testing::Values("timer", "on-sample", "avr"), [](const auto& info) {
    return info.param == "timer" ? std::string("OnTheTimer") : info.param == "avr" ? std::string("OnTheTimerWithTheAvrFirmware") : std::string("OnEachSample");
});

TEST_P(FsmNodeTicking, FollowsTheRightWallAtHalfAMetrePassesTheNicheTakesTheCornerAndStops)
{
    const Drive run = drive("corridor.json", GetParam());
    EXPECT_EQ(run.states, (std::vector<int>{0, 1, 2, 3})) << run.output;
    // Each state is announced on the tick that entered it: entered_ns is that tick's time to the
    // nanosecond (wall clock here, ~1.8e18 ns: a double of seconds would round it to 256 ns).
    for (const auto& s : run.statuses) {
        EXPECT_EQ(s.entered_ns(), s.header().create_stamp().nanoseconds()) << "state " << s.state_id();
    }
    EXPECT_NE(run.output.find("ended in state 3 (Stop)"), std::string::npos) << run.output;
    // --report: the distance, the turn, and each wall-following state's measured deviation from
    // its clearance (the ranger's, niche and corner included: the median is the held line).
    EXPECT_NE(run.output.find("report: driven "), std::string::npos) << run.output;
    for (int state : {0, 2}) {
        const std::string line = "report: state " + std::to_string(state) + ", right wall at 0.50 m";
        const auto at = run.output.find(line);
        ASSERT_NE(at, std::string::npos) << run.output;
        const auto median_at = run.output.find("median ", at);
        ASSERT_NE(median_at, std::string::npos) << run.output;
        EXPECT_LT(std::stod(run.output.substr(median_at + 7)), 0.05) << run.output;
    }
    ASSERT_GT(run.track.size(), 300u);
    ASSERT_GT(run.commands.size(), 300u);
    // The first leg, settled after its first metre, for 5 m (the corner's Motor state starts at
    // x ~ 6.8): the clearance from ground truth within 5 cm of 0.5 m, door niche (x 2.5 .. 3.3)
    // included.
    double worst = 0;
    size_t checked = 0;
    for (auto& o : run.track) {
        if (o.pose().x() > 1.0 && o.pose().x() < 6.0) {
            worst = std::max(worst, std::abs(Drive::clearance(o) - 0.5));
            ++checked;
        }
    }
    EXPECT_GT(checked, 200u);
    EXPECT_LT(worst, 0.05);
    // No steering spike at the niche: a follower that believed the 25 cm jump would steer
    // hard right for as long as it sees the niche (p e alone is 0.75). The rangers' 3 mm noise
    // makes single commands jitter (the d term divides by the 20 ms tick), which the servo
    // smooths; so the check is on the mean over 0.2 s (10 commands).
    double steer_niche = 0, steer_straight = 0;
    for (size_t i = 10; i < run.commands.size(); ++i) {
        double sum = 0;
        for (size_t k = i - 10; k < i; ++k) sum += run.commands[k].steering_servo();
        const double x = run.x_at(run.commands[i]), mean = std::abs(sum / 10);
        if (x > 2.4 && x < 3.5) steer_niche = std::max(steer_niche, mean);
        if (x > 1.0 && x < 2.4) steer_straight = std::max(steer_straight, mean);
    }
    EXPECT_LT(steer_niche, 0.3);
    // The second leg (heading +y along the wall x = 8.0), settled a metre after the corner:
    // the clearance from ground truth within 5 cm of 0.5 m too.
    double worst_second = 0;
    size_t checked_second = 0;
    const double end_y = run.track.back().pose().y();
    for (auto& o : run.track) {
        const double x = o.pose().x(), y = o.pose().y(), yaw = o.pose().yaw();
        if (x < 6.4 || y < 2.8 || y > end_y - 0.05) continue;
        const double ranger_x = x + kRight.x * std::cos(yaw) - kRight.y * std::sin(yaw);
        worst_second = std::max(worst_second, std::abs((8.0 - ranger_x) - 0.5));
        ++checked_second;
    }
    EXPECT_GT(checked_second, 30u);
    EXPECT_LT(worst_second, 0.05) << run.output;
    // Where it must stop: 0.5 m from the right wall (x = 8.0 - 0.5 - 0.09, the ranger's offset),
    // heading up the leg, and once the front ranger (0.30 m ahead) read 0.6 m to the end wall
    // (y = 5.0 - 0.6 - 0.30) plus what 0.5 m/s covers in the 2-tick debounce, the 30 ms actuation
    // delay and the braking (~0.1 s): about 0.05 m.
    const auto& end = run.track.back().pose();
    EXPECT_NEAR(end.yaw(), M_PI / 2, 0.1) << run.output;
    EXPECT_NEAR(end.x(), 8.0 - 0.5 + kRight.y, 0.1) << run.output;
    EXPECT_NEAR(end.y(), 5.0 - 0.6 - kFront.x + 0.05, 0.1) << run.output;
    std::printf("first leg: clearance within %.0f mm of 0.5 m over %zu observations; second leg within %.0f mm over %zu; "
                "|steering| (0.2 s mean) up to %.2f on the straight, %.2f at the niche; stopped at (%.2f, %.2f, %.2f)\n",
                worst * 1000, checked, worst_second * 1000, checked_second, steer_straight, steer_niche, end.x(), end.y(),
                end.yaw());
}

TEST(FsmNodeEndToEnd, RampsTheClearanceFromHalfAMetreToPointEightOverTwoMetres)
{
    const Drive run = drive("lane_change.json");
    EXPECT_EQ(run.states, (std::vector<int>{0, 1, 2, 3})) << run.output;
    ASSERT_GT(run.track.size(), 300u);
    // The ramp runs from x ~ 3.5 to ~ 5.5 (the odometer's 3.5 m and 2 m); from 0.3 m after its
    // end the clearance is within 5 cm of 0.8 m and stays there.
    double before = 0, after_worst = 0;
    for (auto& o : run.track) {
        if (o.pose().x() > 3.0 && o.pose().x() < 3.4) before = std::max(before, std::abs(Drive::clearance(o) - 0.5));
        if (o.pose().x() > 5.8) after_worst = std::max(after_worst, std::abs(Drive::clearance(o) - 0.8));
    }
    EXPECT_LT(before, 0.05) << run.profile();
    EXPECT_LT(after_worst, 0.05) << run.profile() << run.output;
    const double end_clearance = Drive::clearance(run.track.back());
    EXPECT_NEAR(end_clearance, 0.8, 0.05);
    std::printf("before the ramp within %.0f mm of 0.5 m; after it within %.0f mm of 0.8 m; at rest %.3f m\n",
                before * 1000, after_worst * 1000, end_clearance);
}

TEST(FsmNodeEndToEnd, WithoutACarItBrakesAndSaysWhy)
{
    cpm_test::test_domain_id();
    Process sut({built_program("fsm_node"), "--vehicle_id", "6", "--fsm", cpm_test::source_dir() + "/scenarios/fsm/corridor.json"});
    EXPECT_TRUE(cpm_test::wait_until([&] { return sut.errors().find("vehicle 6: no VehicleState; braking") != std::string::npos; }))
        << sut.errors();
    sut.kill(SIGTERM);
    EXPECT_EQ(sut.wait(5s), 0) << sut.errors();
}

TEST(FsmNodeEndToEnd, AMachineWithErrorsIsNotStartedAndEveryErrorIsListed)
{
    cpm_test::test_domain_id();
    const std::string file = "/tmp/cpm_fsm_bad_" + std::to_string(::getpid()) + ".json";
    std::ofstream(file) << R"({"root": 0, "states": [{"id": 0, "type": "FollowWal"}, {"id": 1, "type": "Motor", "speed": "x"}], "transitions": []})";
    Process sut({built_program("fsm_node"), "--vehicle_id", "6", "--fsm", file});
    EXPECT_EQ(sut.wait(10s), 1);
    EXPECT_NE(sut.errors().find(file + ": $.states[0].type: unknown state type \"FollowWal\""), std::string::npos) << sut.errors();
    EXPECT_NE(sut.errors().find(file + ": $.states[1].speed: expected a number"), std::string::npos) << sut.errors();
    EXPECT_NE(sut.errors().find("2 error(s)"), std::string::npos) << sut.errors();
    std::remove(file.c_str());
}

TEST(CpmFsmCheck, ReportsAGoodFileAsOkAndABadOneWithEveryErrorAndExitCode1)
{
    cpm_test::test_domain_id();
    Process good({built_program("cpm"), "fsm", "check", cpm_test::source_dir() + "/scenarios/fsm/corridor.json"});
    EXPECT_EQ(good.wait(10s), 0) << good.output() << good.errors();
    EXPECT_NE(good.output().find("corridor.json: ok (4 states, 3 transitions, 0 warning(s))"), std::string::npos) << good.output();

    const std::string file = "/tmp/cpm_fsm_check_" + std::to_string(::getpid()) + ".json";
    std::ofstream(file) << R"({"root": 0, "states": [{"id": 0, "type": "Motor", "distance": 1}, {"id": 1, "type": "Idle"}],
        "transitions": [{"id": 0, "type": "Finished", "from": 1, "to": 0}, {"id": 1, "type": "Distance", "from": 0, "to": 2}]})";
    Process bad({built_program("cpm"), "fsm", "check", file});
    EXPECT_EQ(bad.wait(10s), 1);
    const std::string out = bad.output();
    EXPECT_NE(out.find("error: " + file + ": $.transitions[0]: Finished from state 1 (Idle), which never finishes"), std::string::npos) << out;
    EXPECT_NE(out.find("error: " + file + ": $.transitions[1].to: state 2 does not exist"), std::string::npos) << out;
    EXPECT_NE(out.find("error: " + file + ": $.transitions[1]: Distance needs parameter \"distance\""), std::string::npos) << out;
    EXPECT_NE(out.find(file + ": 3 error(s)"), std::string::npos) << out;
    std::remove(file.c_str());
}

TEST(CpmFsmConvertAndRender, TheDrawingConvertsToTheJsonAndRendersItsStatesAndTransitions)
{
    cpm_test::test_domain_id();
    const std::string dir = cpm_test::source_dir() + "/scenarios/fsm/";
    Process convert({built_program("cpm"), "fsm", "convert", dir + "corridor.uxf"});
    ASSERT_EQ(convert.wait(10s), 0) << convert.errors();
    std::ifstream json_file(dir + "corridor.json");
    std::stringstream expected;
    expected << json_file.rdbuf();
    EXPECT_EQ(nlohmann::json::parse(convert.output()), nlohmann::json::parse(expected.str()));

    const std::string svg = "/tmp/cpm_fsm_render_" + std::to_string(::getpid()) + ".svg";
    Process render({built_program("cpm"), "fsm", "render", dir + "corridor.uxf", "-o", svg});
    ASSERT_EQ(render.wait(20s), 0) << render.errors();
    std::ifstream in(svg);
    std::stringstream text;
    text << in.rdbuf();
    const std::string s = text.str();
    auto count = [&](const std::string& what) {
        size_t n = 0;
        for (size_t at = s.find(what); at != std::string::npos; at = s.find(what, at + 1)) ++n;
        return n;
    };
    EXPECT_EQ(count("class=\"node\""), 4u);
    EXPECT_EQ(count("class=\"edge\""), 3u);
    for (const char* label : {"0: FollowWall (root)", "1: Motor", "2: FollowWall", "3: Stop", "1: Finished", "2: SensorLevel"}) {
        EXPECT_NE(s.find(label), std::string::npos) << label;
    }
    std::remove(svg.c_str());

    Process wrong({built_program("cpm"), "fsm", "render", dir + "corridor.json", "-o", "/tmp/x.gif"});
    EXPECT_EQ(wrong.wait(10s), 2);
    EXPECT_NE(wrong.errors().find("must end in .svg, .png or .dot"), std::string::npos) << wrong.errors();
}
