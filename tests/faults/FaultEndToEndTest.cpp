// Faults survived, with real processes. A running lab loses one node to kill -9: every other
// process keeps running, the car brakes within the bound of the command it lost (the
// controller's 250 ms watchdog, a command's 1 s freshness), the history marks the dead process
// deleted and keeps what it wrote, and the node started again with the same arguments works
// again within a second.
//
// The lab: car 6 in the gates world (firmware_sim on a pty with a stable --link name,
// vehicle_bridge, camera_sim, aruco_node, fsm_node with the gates machine), cpm_history, a
// parameter server and the monitor; and, for the planner and the time master, two cars on the
// intersection's lanes routed by central_routing under `cpm lab clock`.
#include <cpm/HistoryClient.hpp>
#include <cpm/Participant.hpp>
#include <cpm/AsyncReader.hpp>
#include <cpm/get_parameter.hpp>
#include <cpm/get_time_ns.hpp>

#include <cpm_test/Dds.hpp>
#include <cpm_test/Isolation.hpp>
#include <cpm_test/Process.hpp>
#include <cpm/ProcessGroup.hpp>

#include "SimTrace.hpp"
#include <cpm_test/TempDir.hpp>

#include <ArucoMarkers.h>
#include <VehicleCommandDirect.h>
#include <VehicleCommandTrajectory.h>
#include <VehicleState.h>

#include <gtest/gtest.h>
#include <httplib.h>
#include <nlohmann/json.hpp>

#include <arpa/inet.h>
#include <csignal>
#include <map>
#include <memory>
#include <mutex>
#include <netinet/in.h>
#include <optional>
#include <sstream>
#include <sys/socket.h>
#include <unistd.h>

namespace {

using namespace std::chrono_literals;
using cpm_test::built_program;
using cpm_test::Process;
using cpm_faults::kRoot;
using cpm_faults::first_mode_after;
using cpm_faults::pwm_after;

const std::string kMap = kRoot + "/scenarios/maps/gates.json";
const std::string kCamera = kRoot + "/scenarios/cameras/sim_640x480.yaml";
const std::string kMachine = kRoot + "/scenarios/fsm/gates.json";
const std::string kLanes = kRoot + "/scenarios/lanes/intersection.json";
constexpr uint64_t kMsNs = 1'000'000;
/// How soon a node started again must work, seconds. Typically 50-300 ms here (the history and
/// the parameter server up to 0.7 s), single runs up to 1.22 s (a restarted clock's first
/// discovery), 1.62 s with a busy loop on one core beside the suite. What the bound tells apart
/// is a restart that works at once from one that waits for the dead process's lease (3 s
/// here, below) or a timeout: 2.5 s does, without failing a loaded machine. Each test prints
/// its figure. Under a sanitizer (every process 5-15 times slower; the monitor took 3.2 s
/// there) 4.5 s: such a run looks for races and memory errors.
#ifdef CPM_TEST_SANITIZED
constexpr double kRestartBound = 4.5;
#else
constexpr double kRestartBound = 2.5;
#endif
/// Every process of the lab runs with a 3 s lease (--dds_lease), so that the history marks a
/// killed one dead after 3 s instead of the default 10 (the suite runs alone; a process
/// starved for 3 s is not expected here). Under a sanitizer the default.
#ifdef CPM_TEST_SANITIZED
const std::vector<std::string> kLease;
#else
const std::vector<std::string> kLease{"CPM_DDS_LEASE=3s"};
#endif

/// When the samples of one topic arrived here (cpm::get_time_ns), and the newest create stamp.
class Arrivals
{
public:
    template <class T>
    Arrivals(cpm::Participant& participant, const std::string& topic, T* /*type*/)
        : reader_(std::make_shared<cpm::AsyncReader<T>>(
              [this](std::vector<T>& batch) {
                  const uint64_t now = cpm::get_time_ns();
                  std::lock_guard lock(mutex_);
                  for (const auto& s : batch) {
                      times_.push_back(now);
                      newest_stamp_ = std::max(newest_stamp_, s.header().create_stamp().nanoseconds());
                  }
              },
              participant, topic, cpm::ReaderOptions{.keep_all = true}))
    {
    }
    /// The first arrival after t, if any.
    std::optional<uint64_t> first_after(uint64_t t) const
    {
        std::lock_guard lock(mutex_);
        for (uint64_t a : times_)
            if (a > t) return a;
        return std::nullopt;
    }
    size_t count_between(uint64_t t0, uint64_t t1) const
    {
        std::lock_guard lock(mutex_);
        size_t n = 0;
        for (uint64_t a : times_) n += a > t0 && a <= t1;
        return n;
    }
    uint64_t newest_stamp() const
    {
        std::lock_guard lock(mutex_);
        return newest_stamp_;
    }

private:
    mutable std::mutex mutex_;
    std::vector<uint64_t> times_;
    uint64_t newest_stamp_ = 0;
    std::shared_ptr<void> reader_;
};

/// A lab of named processes (one cpm::ProcessGroup, as a lab run has), each started again with
/// the arguments it first had; each one's stdout and stderr in its log.
class Lab
{
public:
    cpm_test::TempDir tmp;
    cpm::Participant participant{cpm_test::isolated_options()};

    void start(const std::string& name, std::vector<std::string> argv)
    {
        (void)group_.start({.name = name, .argv = std::move(argv), .env = kLease, .log = tmp.file(name + ".log")});
    }
    void restart(const std::string& name) { (void)group_.restart(name); }
    cpm::ChildProcess& operator[](const std::string& name) { return *group_.find(name); }
    /// Everything it wrote since it was last started (a restart appends to its log).
    std::string output(const std::string& name) const
    {
        const std::string all = group_.log_text(name);
        const std::string mark = "\n--- restarted ---\n";
        const auto at = all.rfind(mark);
        return at == std::string::npos ? all : all.substr(at + mark.size());
    }
    /// Its exit code once it ended within `timeout`, else -1 (also when a signal ended it).
    int wait(const std::string& name, std::chrono::milliseconds timeout)
    {
        const auto end = group_.find(name)->wait(timeout);
        return end && end->signal == 0 ? end->code : -1;
    }
    /// kill -9; the time of the kill.
    uint64_t kill9(const std::string& name)
    {
        const uint64_t t = cpm::get_time_ns();
        group_.find(name)->signal(SIGKILL);
        (void)group_.find(name)->wait(5s);
        return t;
    }
    /// The processes other than `except` that are no longer running, with their output.
    std::string ended_others(const std::string& except)
    {
        std::string out;
        for (const auto& name : group_.names()) {
            if (name != except && group_.find(name)->ended()) out += name + " ended:\n" + output(name) + "\n";
        }
        return out;
    }
    std::string logs() const
    {
        std::string out;
        for (const auto& name : group_.names()) out += "--- " + name + ":\n" + group_.tail(name, 30) + "\n";
        return out;
    }
    /// Restarts `name` and returns the seconds until `works` holds (checked every 5 ms; 10 s at most).
    double restart_until(const std::string& name, const std::function<bool(uint64_t)>& works)
    {
        const uint64_t restarted = cpm::get_time_ns();
        restart(name);
        const bool ok = cpm_test::wait_until([&] { return works(restarted); }, 10s, 5ms);
        const double took = double(cpm::get_time_ns() - restarted) * 1e-9;
        EXPECT_TRUE(ok) << name << " started again did not work within 10 s\n" << logs();
        std::printf("%s: restarted and working after %.0f ms\n", name.c_str(), took * 1000);
        return ok ? took : 1e9;
    }

private:
    cpm::ProcessGroup group_;  // last: stopped before the folder of its logs goes
};

/// Every process object the history holds, for a failure's message: "name (alive|deleted)".
std::string process_list(cpm::HistoryClient& history)
{
    HistoryRequest rq = cpm::HistoryClient::make(cpm::history::Kind::search, "", "");
    const HistoryReply reply = history.request(rq);  // the objects live as long as the reply
    std::string out;
    for (const auto& o : reply.objects())
        if (o.is_process()) out += o.name() + (o.deleted_ts() == 0 ? " (alive)\n" : " (deleted)\n");
    return out;
}

/// The history's process objects with this participant name: (alive, deleted) counts.
std::pair<int, int> process_objects(cpm::HistoryClient& history, const std::string& name)
{
    HistoryRequest rq = cpm::HistoryClient::make(cpm::history::Kind::search, "", "");
    rq.name_regex("^" + name + "$");
    const HistoryReply reply = history.request(rq);
    int alive = 0, deleted = 0;
    for (const auto& o : reply.objects()) {
        if (!o.is_process()) continue;
        ++(o.deleted_ts() == 0 ? alive : deleted);
    }
    return {alive, deleted};
}

/// Car 6 in the gates world with everything a car of the lab has around it.
class CarLab : public ::testing::Test
{
protected:
    Lab lab;
    std::string link = lab.tmp.file("car6.tty");
    int port = cpm_test::free_tcp_port();
    Arrivals states{lab.participant, "vehicleState", static_cast<VehicleState*>(nullptr)};
    Arrivals commands{lab.participant, "vehicleCommandDirect", static_cast<VehicleCommandDirect*>(nullptr)};
    Arrivals markers{lab.participant, "arucoMarkers", static_cast<ArucoMarkers*>(nullptr)};
    std::unique_ptr<cpm::HistoryClient> history;

    void SetUp() override
    {
        lab.start("history", {built_program("cpm_history"), "--window", "60s", "--exclude", "cameraFrame"});
        lab.start("param", {built_program("cpm"), "param", "serve", lab.tmp.write("params.json", R"({"before": 1})")});
        lab.start("sim", {built_program("firmware_sim"), "--vehicle_id", "6", "--map", kMap, "--start", "0,0,0.3", "--link", link,
                          "--trace-pwm"});
        ASSERT_TRUE(cpm_test::wait_until([&] { return lab.output("sim").find("device: ") != std::string::npos; }, 10s))
            << lab.output("sim");
        lab.start("bridge", {built_program("vehicle_bridge"), "--vehicle_id", "6", "--device", link, "--start", "0,0,0.3"});
        lab.start("camera", {built_program("camera_sim"), "--vehicle_id", "6", "--camera", kCamera, "--map", kMap, "--rate", "20"});
        lab.start("aruco", {built_program("aruco_node"), "--vehicle_id", "6", "--camera", kCamera, "--world", kMap});
        lab.start("monitor", {built_program("cpm"), "monitor", "--port", std::to_string(port), "--world", kMap});
        lab.start("fsm", {built_program("fsm_node"), "--vehicle_id", "6", "--fsm", kMachine});
        history = std::make_unique<cpm::HistoryClient>(lab.participant);
        // Running: the car drives forward on the machine's commands, markers are seen, the
        // history holds the car's state and its markers (the kill tests ask it for both).
        ASSERT_TRUE(cpm_test::wait_until(
            [&] {
                const auto pwm = pwm_after(lab.output("sim"), 0);
                return !pwm.empty() && pwm.back().second == 1 && markers.first_after(0) &&
                       history->latest("vehicleState", "6").status() == "ok" &&
                       history->latest("arucoMarkers", "6").status() == "ok";
            },
            30s, 20ms))
            << lab.logs();
        std::this_thread::sleep_for(500ms);
    }

    /// The monitor's /api/state shows car 6, with a pose newer than t.
    bool monitor_shows_car(uint64_t t)
    {
        httplib::Client http("127.0.0.1", port);
        http.set_connection_timeout(0, 200'000);
        auto r = http.Get("/api/state");
        if (!r || r->status != 200) return false;
        const auto state = nlohmann::json::parse(r->body, nullptr, false);
        if (!state.is_object() || !state.contains("vehicles")) return false;
        for (const auto& v : state["vehicles"]) {
            if (v.value("id", 0) == 6 && v.value("state_stamp_ns", uint64_t(0)) > t) return true;
        }
        return false;
    }

    /// After kill -9 of `name` (at `killed`): the history marks its process deleted (once its
    /// participant's lease has run out), keeps it listed, and still answers what it wrote.
    void expect_history_marks_dead(const std::string& participant_name, uint64_t killed, const std::string& topic = "",
                                   const std::string& key = "")
    {
        EXPECT_TRUE(cpm_test::wait_until([&] { return process_objects(*history, participant_name).second >= 1; }, 20s, 200ms))
            << "the history never marked " << participant_name << " dead; it holds:\n" << process_list(*history);
        if (!topic.empty()) {
            const HistoryReply before = history->at(topic, key, killed - 100 * kMsNs);
            EXPECT_TRUE(before.status() == "ok" && !before.samples().empty())
                << topic << "/" << key << " as it was before the kill: " << before.status() << " " << before.error();
        }
    }

    /// What the watchdogs did after a kill: the first brake (mode 0) after t, in seconds after t.
    double brake_after(uint64_t t)
    {
        EXPECT_TRUE(cpm_test::wait_until([&] { return first_mode_after(lab.output("sim"), t, 0) != 0; }, 3s));
        const uint64_t braked = first_mode_after(lab.output("sim"), t, 0);
        return braked != 0 ? double(braked - t) * 1e-9 : 1e9;
    }

    /// The car drives forward on commands written after t.
    bool drives_after(uint64_t t) { return first_mode_after(lab.output("sim"), t, 1) != 0; }
};

TEST_F(CarLab, KillingTheStateMachineBrakesTheCarWithinTheCommandsFreshnessAndItsRestartDrivesAgain)
{
    // The newest command this test has seen (the car drives on them; this reader may match later).
    ASSERT_TRUE(cpm_test::wait_until([&] { return commands.newest_stamp() != 0; }, 10s)) << lab.logs();
    const uint64_t last_command = commands.newest_stamp();
    const uint64_t killed = lab.kill9("fsm");
    // Its newest command goes stale 1 s after it was made; the bridge brakes on its next cycle.
    const double braked = brake_after(killed);
    EXPECT_LT(braked, 1.1) << "braked " << braked << " s after the kill";
    EXPECT_GT(double(killed + uint64_t(braked * 1e9) - last_command) * 1e-9, 0.95) << "braked while its command was fresh";
    EXPECT_EQ(lab.ended_others("fsm"), "");
    EXPECT_LT(lab.restart_until("fsm", [&](uint64_t t) { return commands.first_after(t).has_value(); }), kRestartBound);
    EXPECT_TRUE(cpm_test::wait_until([&] { return drives_after(killed + uint64_t(braked * 1e9)); }, 5s)) << lab.logs();
    expect_history_marks_dead("fsm_node", killed, "vehicleCommandDirect", "6");
    EXPECT_EQ(lab.ended_others(""), "");
}

TEST_F(CarLab, KillingTheBridgeLetsTheControllersWatchdogBrakeAndItsRestartDrivesAgain)
{
    const uint64_t killed = lab.kill9("bridge");
    const double braked = brake_after(killed);
    EXPECT_LT(braked, 0.3) << "the controller's watchdog brakes 250 ms after the last command";
    EXPECT_EQ(lab.ended_others("bridge"), "");
    EXPECT_LT(lab.restart_until("bridge", [&](uint64_t t) { return states.first_after(t).has_value(); }), kRestartBound);
    EXPECT_TRUE(cpm_test::wait_until([&] { return drives_after(killed + uint64_t(braked * 1e9)); }, 5s)) << lab.logs();
    expect_history_marks_dead("vehicle_bridge", killed, "vehicleState", "6");
    EXPECT_EQ(lab.ended_others(""), "");
}

TEST_F(CarLab, KillingTheSimulatorStopsTheCarsStatesAndItsRestartIsTakenBackByTheSameBridge)
{
    const uint64_t killed = lab.kill9("sim");
    // Nothing the car measured after it was gone is published; the machine brakes on stale input.
    EXPECT_TRUE(cpm_test::holds_for([&] { return states.newest_stamp() < killed + 30 * kMsNs; }, 1s));
    EXPECT_EQ(lab.ended_others("sim"), "");
    EXPECT_LT(lab.restart_until("sim", [&](uint64_t t) { return states.newest_stamp() > t; }), kRestartBound);
    EXPECT_TRUE(cpm_test::wait_until([&] { return drives_after(0); }, 5s)) << lab.logs();
    expect_history_marks_dead("firmware_sim", killed);
    EXPECT_EQ(lab.ended_others(""), "");
}

TEST_F(CarLab, KillingTheCameraLeavesTheMarkerFinderWaitingAndItsRestartFeedsItAgain)
{
    const uint64_t killed = lab.kill9("camera");
    std::this_thread::sleep_for(300ms);
    const uint64_t quiet = cpm::get_time_ns();
    EXPECT_TRUE(cpm_test::holds_for([&] { return !markers.first_after(quiet); }, 500ms)) << "no frames, no markers";
    EXPECT_GT(commands.count_between(killed, cpm::get_time_ns()), 20u) << "the machine goes on";
    EXPECT_EQ(lab.ended_others("camera"), "");
    EXPECT_LT(lab.restart_until("camera", [&](uint64_t t) { return markers.first_after(t).has_value(); }), kRestartBound);
    expect_history_marks_dead("camera_sim", killed);
    EXPECT_EQ(lab.ended_others(""), "");
}

TEST_F(CarLab, KillingTheMarkerFinderLeavesTheMachineDrivingAndItsRestartSeesMarkersAgain)
{
    const uint64_t killed = lab.kill9("aruco");
    std::this_thread::sleep_for(1s);
    EXPECT_GT(commands.count_between(killed, cpm::get_time_ns()), 20u) << "the machine goes on";
    EXPECT_EQ(lab.ended_others("aruco"), "");
    EXPECT_LT(lab.restart_until("aruco", [&](uint64_t t) { return markers.first_after(t).has_value(); }), kRestartBound);
    expect_history_marks_dead("aruco_node", killed, "arucoMarkers", "6");
    EXPECT_EQ(lab.ended_others(""), "");
}

TEST_F(CarLab, KillingTheHistoryLeavesTheLabDrivingAndItsRestartAnswersAgain)
{
    const uint64_t killed = lab.kill9("history");
    std::this_thread::sleep_for(1s);
    EXPECT_GT(commands.count_between(killed, cpm::get_time_ns()), 20u) << "the machine goes on";
    EXPECT_EQ(lab.ended_others("history"), "");
    // The same client as before the kill: a long-lived process asking a history that is new.
    EXPECT_LT(lab.restart_until("history",
                            [&](uint64_t t) {
                                const HistoryReply r = history->latest("vehicleState", "6");
                                return r.status() == "ok" && !r.samples().empty() && r.samples()[0].commit_ns() > t;
                            }), kRestartBound);
    // What it held died with it (it keeps no file without --record); the restarted one sees
    // the old one's process object as a process that is gone.
    EXPECT_EQ(lab.ended_others(""), "");
}

TEST_F(CarLab, KillingTheParameterServerKeepsTheLabAndItsRestartAnswersRequests)
{
    EXPECT_EQ(cpm::parameter_int("before", 5s), 1);
    const uint64_t killed = lab.kill9("param");
    std::this_thread::sleep_for(1s);
    EXPECT_GT(commands.count_between(killed, cpm::get_time_ns()), 20u) << "the machine goes on";
    EXPECT_EQ(lab.ended_others("param"), "");
    // The file gets a parameter the dead server never had: only the new one can answer it.
    lab.tmp.write("params.json", R"({"before": 1, "after": 2})");
    int32_t after = 0;
    EXPECT_LT(lab.restart_until("param",
                            [&](uint64_t) {
                                try {
                                    after = cpm::parameter_int("after", 2ms);
                                    return true;
                                } catch (const std::exception&) {
                                    return false;
                                }
                            }), kRestartBound);
    EXPECT_EQ(after, 2);
    expect_history_marks_dead("cpm", killed);
    EXPECT_EQ(lab.ended_others(""), "");
}

TEST_F(CarLab, KillingTheMonitorKeepsTheLabAndItsRestartServesTheSamePortAgain)
{
    ASSERT_TRUE(cpm_test::wait_until([&] { return monitor_shows_car(0); }, 10s)) << lab.output("monitor");
    const uint64_t killed = lab.kill9("monitor");
    std::this_thread::sleep_for(1s);
    EXPECT_GT(commands.count_between(killed, cpm::get_time_ns()), 20u) << "the machine goes on";
    EXPECT_EQ(lab.ended_others("monitor"), "");
    EXPECT_LT(lab.restart_until("monitor", [&](uint64_t t) { return monitor_shows_car(t); }), kRestartBound);
    EXPECT_EQ(lab.ended_others(""), "");
}

}  // namespace

namespace {

/// Two cars on the intersection's lanes, planned by central_routing, started by the lab's
/// clock (real time), with the history.
class RoutedLab : public ::testing::Test
{
protected:
    Lab lab;
    Arrivals trajectories{lab.participant, "vehicleCommandTrajectory", static_cast<VehicleCommandTrajectory*>(nullptr)};
    std::mutex mutex;
    std::map<int, std::pair<uint64_t, double>> speed;  // car: (stamp, speed) of its newest state
    cpm::AsyncReader<VehicleState> states{[this](std::vector<VehicleState>& batch) {
                                              std::lock_guard lock(mutex);
                                              for (const auto& s : batch)
                                                  speed[s.vehicle_id()] = {s.header().create_stamp().nanoseconds(), s.speed()};
                                          },
                                          lab.participant, "vehicleState"};
    std::unique_ptr<cpm::HistoryClient> history;

    void SetUp() override
    {
        lab.start("history", {built_program("cpm_history"), "--window", "60s"});
        lab.start("cars", {built_program("cpm"), "vehicle", "sim", "--id", "1", "--count", "2", "--lanes", kLanes, "--seed", "1"});
        lab.start("routing", {built_program("central_routing"), "--vehicle_ids", "1,2", "--lanes", kLanes, "--seed", "1"});
        lab.start("clock", {built_program("cpm"), "lab", "clock", "--nodes", "central_routing", "--start-delay", "200ms"});
        history = std::make_unique<cpm::HistoryClient>(lab.participant);
        ASSERT_TRUE(cpm_test::wait_until([&] { return fastest() > 0.2; }, 30s, 20ms)) << lab.logs();
    }
    /// The fastest car's newest speed.
    double fastest()
    {
        std::lock_guard lock(mutex);
        double v = 0;
        for (const auto& [id, s] : speed) v = std::max(v, std::abs(s.second));
        return speed.size() == 2 ? v : 0;
    }
    /// Both cars stand (their newest states made after t say so).
    bool both_stand_after(uint64_t t)
    {
        std::lock_guard lock(mutex);
        int standing = 0;
        for (const auto& [id, s] : speed) standing += s.first > t && std::abs(s.second) < 0.02;
        return standing == 2;
    }
};

TEST_F(RoutedLab, KillingThePlannerStopsTheCarsWithinTheTrajectorysFreshnessAndItsRestartRoutesThemAgain)
{
    // The newest trajectory this test has seen (the cars drive on them; this reader may match later).
    ASSERT_TRUE(cpm_test::wait_until([&] { return trajectories.newest_stamp() != 0; }, 10s)) << lab.logs();
    const uint64_t newest = trajectories.newest_stamp();
    const uint64_t killed = lab.kill9("routing");
    // The newest trajectory is fresh for 1 s after it was made, then the bridge brakes; a car at
    // 1 m/s stands about half a second later.
    EXPECT_TRUE(cpm_test::wait_until([&] { return both_stand_after(killed); }, 5s)) << lab.logs();
    const double stood = double(cpm::get_time_ns() - newest) * 1e-9;
    EXPECT_LT(stood, 2.0) << "the cars stood " << stood << " s after the newest trajectory was made";
    EXPECT_EQ(lab.ended_others("routing"), "");
    // Its lab timer ticks on the lab's 400 ms grid: the first plan comes at the first tick after
    // it has joined, up to one period later than a node that acts at once.
    EXPECT_LT(lab.restart_until("routing", [&](uint64_t t) { return trajectories.first_after(t).has_value(); }), kRestartBound + 0.4);
    EXPECT_TRUE(cpm_test::wait_until([&] { return fastest() > 0.2; }, 10s)) << "the cars drive again\n" << lab.logs();
    EXPECT_TRUE(cpm_test::wait_until([&] { return process_objects(*history, "central_routing").second >= 1; }, 20s, 200ms))
        << process_list(*history);
    EXPECT_EQ(lab.ended_others(""), "");
}

TEST_F(RoutedLab, KillingTheTimeMasterLeavesTheTimersRunningAndItsRestartCanStopThem)
{
    const uint64_t killed = lab.kill9("clock");
    std::this_thread::sleep_for(1500ms);
    EXPECT_GT(trajectories.count_between(killed, cpm::get_time_ns()), 2u) << "the planner's timer goes on";
    EXPECT_EQ(lab.ended_others("clock"), "");
    // Started again with the same arguments it finds the running planner's timer and starts it
    // (a start a running timer ignores); Ctrl-C then stops every timer, the planner's too.
    EXPECT_LT(lab.restart_until("clock", [&](uint64_t) { return lab.output("clock").find("all 1 nodes ready") != std::string::npos; }), kRestartBound);
    // The history marks the killed master dead (a process named "cpm", the only one that ended).
    EXPECT_TRUE(cpm_test::wait_until([&] { return process_objects(*history, "cpm").second >= 1; }, 20s, 200ms))
        << process_list(*history);
    EXPECT_EQ(lab.ended_others(""), "");
    lab["clock"].signal(SIGINT);
    EXPECT_EQ(lab.wait("clock", 10s), 0) << lab.output("clock");
    EXPECT_EQ(lab.wait("routing", 10s), 0) << "the restarted clock's stop ends the planner\n" << lab.logs();
}

}  // namespace
