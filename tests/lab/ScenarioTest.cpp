// Lab scenarios read and checked: the shipped ones load and plan the processes a run needs; a
// wrong file gives every error at once, each with its line and YAML path.
#include <cpm/Error.hpp>
#include <cpm/lab/Scenario.hpp>

#include <cpm_test/TempDir.hpp>
#include <cpm_test/SourceDir.hpp>

#include <gtest/gtest.h>

#include <sys/stat.h>

#include <filesystem>
#include <map>
#include <fstream>

namespace fs = std::filesystem;
using namespace cpm::lab;

using cpm_test::TempDir;

namespace {


std::string labs(const std::string& name) { return cpm_test::source_dir() + "/scenarios/labs/" + name; }

std::vector<std::string> errors_of(const std::string& file)
{
    try {
        (void)load_scenario(file);
    } catch (const ScenarioError& e) {
        return e.errors();
    }
    return {};
}

/// A fake bin folder holding the programs a run needs (empty executables).
std::string fake_bin(const TempDir& dir, const std::vector<std::string>& programs)
{
    fs::create_directories(dir.path / "bin");
    for (const auto& p : programs) {
        std::ofstream(dir.path / "bin" / p) << "";
        fs::permissions(dir.path / "bin" / p, fs::perms::owner_all);
    }
    return (dir.path / "bin").string();
}

}  // namespace

TEST(Scenario, TheShippedScenariosLoadAndPlanTheirProcesses)
{
    TempDir dir;
    const std::string bin =
        fake_bin(dir, {"cpm", "cpm_history", "fsm_node", "aruco_node", "central_routing", "firmware_sim", "vehicle_bridge", "camera_sim"});
    const Scenario corridor = load_scenario(labs("corridor.yaml"));
    EXPECT_EQ(corridor.name, "corridor");
    EXPECT_EQ(corridor.time, TimeMode::simulated);
    EXPECT_EQ(corridor.duration_ns, 40'000'000'000ull);
    ASSERT_EQ(corridor.vehicles.size(), 1u);
    EXPECT_EQ(corridor.vehicles[0].id, 5);
    EXPECT_DOUBLE_EQ(corridor.vehicles[0].y, -0.01);
    EXPECT_EQ(corridor.world, fs::weakly_canonical(cpm_test::source_dir() + "/scenarios/maps/corridor.json").string());
    auto plan = plan_run(corridor, {.bin_dir = bin, .run_dir = "/runs/x", .domain = 7, .time = TimeMode::simulated});
    ASSERT_EQ(plan.size(), 5u);
    EXPECT_EQ(plan[0].name, "cpm_history");
    // The monitor (monitor: 8080) comes before the cars, so that it shows the run from its start.
    EXPECT_EQ(plan[1].name, "monitor");
    EXPECT_EQ(std::vector<std::string>(plan[1].argv.begin() + 1, plan[1].argv.end()),
              (std::vector<std::string>{"monitor", "--port", "8080", "--world", corridor.world, "--dds_domain", "7"}));
    // The car's simulator and bridge, each supervised by the run, joined by a link in its folder.
    EXPECT_EQ(plan[2].name, "sim_5");
    EXPECT_EQ(std::vector<std::string>(plan[2].argv.begin() + 1, plan[2].argv.end()),
              (std::vector<std::string>{"--vehicle_id", "5", "--map", corridor.world, "--start", "0,-0.01,0", "--link", "/runs/x/car_5.tty",
                                        "--dds_domain", "7", "--simulated_time"}));
    EXPECT_EQ(plan[3].name, "bridge_5");
    EXPECT_EQ(std::vector<std::string>(plan[3].argv.begin() + 1, plan[3].argv.begin() + 5),
              (std::vector<std::string>{"--vehicle_id", "5", "--device", "/runs/x/car_5.tty"}));
    EXPECT_LT(plan[3].stop_order, plan[2].stop_order) << "the bridge stops before its simulator";
    EXPECT_EQ(plan[4].name, "fsm_5");
    // The state machine follows the simulated clock with the car: the clock waits for all three.
    EXPECT_EQ(plan[4].argv.back(), "--simulated_time");
    EXPECT_EQ(plan[4].timer, "fsm_node_5");
    EXPECT_EQ(plan[2].timer, "firmware_sim_5");
    EXPECT_EQ(plan[3].timer, "vehicle_bridge_5");
    EXPECT_NE(std::find(plan[0].argv.begin(), plan[0].argv.end(), "/runs/x/recording.db"), plan[0].argv.end());
    for (const auto& p : plan) {
        auto d = std::find(p.argv.begin(), p.argv.end(), "--dds_domain");
        ASSERT_NE(d, p.argv.end()) << p.name;
        EXPECT_EQ(*(d + 1), "7") << p.name;
    }

    const Scenario gates = load_scenario(labs("gates.yaml"));
    plan = plan_run(gates, {.bin_dir = bin, .run_dir = "/runs/g"});
    ASSERT_EQ(plan.size(), 7u);
    EXPECT_EQ(plan[4].name, "camera_6");
    EXPECT_EQ(plan[5].name, "aruco_6");
    EXPECT_EQ(gates.record.exclude, std::vector<std::string>{"cameraFrame"});

    const Scenario crossing = load_scenario(labs("intersection.yaml"));
    EXPECT_EQ(crossing.time, TimeMode::simulated);
    EXPECT_TRUE(crossing.routing.enabled);
    plan = plan_run(crossing, {.bin_dir = bin, .run_dir = "/runs/i", .time = TimeMode::simulated});
    ASSERT_EQ(plan.size(), 4u);
    EXPECT_EQ(plan[1].name, "monitor");
    EXPECT_NE(std::find(plan[1].argv.begin(), plan[1].argv.end(), "--lanes"), plan[1].argv.end()) << "the monitor draws the lanes";
    EXPECT_EQ(plan[2].name, "cars");
    EXPECT_EQ(plan[2].timer, "firmware_sim_1,vehicle_bridge_1");
    EXPECT_EQ(plan[3].name, "central_routing");
    EXPECT_EQ(plan[3].argv.back(), "--simulated_time");

    // The loop: four cars whose machines drive until stopped, in real time, with stop buttons.
    const Scenario loop = load_scenario(labs("loop.yaml"));
    EXPECT_EQ(loop.time, TimeMode::real);
    ASSERT_EQ(loop.vehicles.size(), 4u);
    EXPECT_EQ(loop.monitor_port, std::optional<int>(8080));
    EXPECT_TRUE(loop.monitor_allow_stop);
    for (const auto& v : loop.vehicles) EXPECT_EQ(v.fsm, fs::weakly_canonical(cpm_test::source_dir() + "/scenarios/fsm/loop.json").string());
}

TEST(Scenario, TimeoutsSayHowLongTheRunWaitsForItsProcessesAndForEachSimulatedStep)
{
    TempDir dir;
    dir.write("map.json", "{\"walls\": []}");
    const std::string head = "name: t\nduration: 5s\nworld: map.json\nvehicles: [{id: 2}]\n";
    // Unsaid: 30 s for the processes to come up (a host reached over ssh is slow), 10 s a step.
    const Scenario plain = load_scenario(dir.write("plain.yaml", head));
    EXPECT_EQ(plain.timeouts.start_ns, 30'000'000'000u);
    EXPECT_EQ(plain.timeouts.step_ns, 10'000'000'000u);
    const Scenario s = load_scenario(dir.write("t.yaml", head + "timeouts: {start: 2m, step: 500ms}\n"));
    EXPECT_EQ(s.timeouts.start_ns, 120'000'000'000u);
    EXPECT_EQ(s.timeouts.step_ns, 500'000'000u);
    const Scenario one = load_scenario(dir.write("one.yaml", head + "timeouts: {step: 3s}\n"));
    EXPECT_EQ(one.timeouts.start_ns, 30'000'000'000u) << "the other keeps its default";
    EXPECT_EQ(one.timeouts.step_ns, 3'000'000'000u);

    const std::string bad = dir.write("bad.yaml", head + "timeouts: {start: 0s, setp: 1s, step: 900us}\n");
    EXPECT_EQ(errors_of(bad), (std::vector<std::string>{
                                  bad + ":5: timeouts.setp: unknown key (did you mean 'step'?); known: start, step",
                                  bad + ":5: timeouts.start: must be longer than 0",
                                  bad + ":5: timeouts.step: must be at least 1ms",
                              }));
    const std::string scalar = dir.write("scalar.yaml", head + "timeouts: 5s\n");
    EXPECT_EQ(errors_of(scalar), (std::vector<std::string>{scalar + ":5: timeouts: expected a map (start, step)"}));
}

TEST(Scenario, AMonitorIsAPortOrAPortWithItsStopButtons)
{
    TempDir dir;
    dir.write("map.json", "{\"walls\": []}");
    const std::string bin = fake_bin(dir, {"cpm_history", "cpm", "firmware_sim", "vehicle_bridge"});
    Scenario s = load_scenario(dir.write("m.yaml", "name: m\nduration: 5s\nworld: map.json\nvehicles: [{id: 2}]\n"
                                                   "monitor: {port: 9000, allow_stop: true}\n"));
    EXPECT_EQ(s.monitor_port, std::optional<int>(9000));
    EXPECT_TRUE(s.monitor_allow_stop);
    const auto plan = plan_run(s, {.bin_dir = bin, .run_dir = "/runs/m", .domain = 3});
    ASSERT_EQ(plan[1].name, "monitor");
    EXPECT_NE(std::find(plan[1].argv.begin(), plan[1].argv.end(), "--allow-stop"), plan[1].argv.end());
    // None, as with --monitor off.
    for (const char* off : {"off", "false", "none"}) {
        const Scenario none = load_scenario(dir.write("off.yaml", "name: m\nduration: 5s\nworld: map.json\nvehicles: [{id: 2}]\nmonitor: " +
                                                                      std::string(off) + "\n"));
        EXPECT_FALSE(none.monitor_port) << off;
    }
    const std::string bad = dir.write("b.yaml", "name: b\nduration: 5s\nworld: map.json\nvehicles: [{id: 2}]\n"
                                                "monitor: {port: 70000, stop: yes}\n");
    try {
        load_scenario(bad);
        FAIL() << "a wrong monitor must be refused";
    } catch (const cpm::lab::ScenarioError& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find(bad + ":5: monitor.port: "), std::string::npos) << what;
        EXPECT_NE(what.find("monitor.stop: unknown key"), std::string::npos) << what;
    }
}

TEST(Scenario, QosOverridesAndAParameterFileReachEveryNode)
{
    TempDir dir;
    dir.write("map.json", "{\"walls\": []}");
    dir.write("lab.yaml", "speed: 0.5\n");
    const std::string file = dir.write("q.yaml", "name: q\nduration: 5s\nworld: map.json\nparameters: lab.yaml\nvehicles: [{id: 2}]\n"
                                                 "qos: {vehicleState: {reliable: true, history_depth: 4}, log: {transient_local: false}}\n");
    const Scenario s = load_scenario(file);
    EXPECT_EQ(s.parameters, fs::weakly_canonical(dir.path / "lab.yaml").string());
    // What the run puts into CPM_QOS_OVERRIDES reads back as the file said.
    const auto back = cpm::parse_qos_overrides(cpm::to_json(s.qos), "test");
    ASSERT_EQ(back.size(), 2u);
    EXPECT_EQ(back.at("vehicleState").reliable, std::optional<bool>(true));
    EXPECT_EQ(back.at("vehicleState").history_depth, std::optional<int>(4));
    EXPECT_FALSE(back.at("vehicleState").transient_local);
    EXPECT_EQ(back.at("log").transient_local, std::optional<bool>(false));
    const auto applied = cpm::overridden(cpm::WriterOptions{.reliable = false, .keep_all = true}, "vehicleState", back);
    EXPECT_TRUE(applied.reliable);
    EXPECT_FALSE(applied.keep_all) << "a history depth means keep the last N";
    EXPECT_EQ(applied.history_depth, 4);
    EXPECT_FALSE(cpm::overridden(cpm::ReaderOptions{}, "rangeSensors", back).reliable) << "other topics keep their own";

    const auto plan = plan_run(s, {.bin_dir = fake_bin(dir, {"cpm_history", "cpm", "firmware_sim", "vehicle_bridge"}), .run_dir = "/runs/q", .domain = 3});
    ASSERT_EQ(plan.size(), 4u);  // history, parameters, the car's simulator and bridge
    EXPECT_EQ(plan[1].name, "parameters");
    EXPECT_EQ(std::vector<std::string>(plan[1].argv.begin() + 1, plan[1].argv.end()),
              (std::vector<std::string>{"param", "serve", s.parameters, "--dds_domain", "3"}));
}

TEST(QosOverrides, AWrongOverrideNamesItsPathAndValue)
{
    auto error_of = [](const std::string& json) {
        try {
            (void)cpm::parse_qos_overrides(json, "CPM_QOS_OVERRIDES");
        } catch (const cpm::Error& e) {
            return std::string(e.what());
        }
        return std::string();
    };
    EXPECT_EQ(error_of("{\"a\": {\"history_depth\": 0}}"), "CPM_QOS_OVERRIDES: a.history_depth: 0 is not a whole number from 1 to 100000");
    EXPECT_EQ(error_of("{\"a\": {\"reliabel\": true}}"), "CPM_QOS_OVERRIDES: a.reliabel: unknown key; known: reliable, transient_local, history_depth");
    EXPECT_EQ(error_of("{\"a\": 1}"), "CPM_QOS_OVERRIDES: a: expected an object (reliable, transient_local, history_depth)");
    EXPECT_EQ(error_of("[1]"), "CPM_QOS_OVERRIDES: expected an object of topic: {reliable, transient_local, history_depth}");
    EXPECT_EQ(error_of("{").rfind("CPM_QOS_OVERRIDES: not JSON: ", 0), 0u);
    EXPECT_EQ(error_of("{}"), "");
}

TEST(Scenario, EveryErrorIsNamedAtOnceWithItsLineAndPath)
{
    TempDir dir;
    dir.write("map.json", "{\"walls\": []}");
    const std::string file = dir.write("bad.yaml",
                                       "name: bad run\n"                     // 1
                                       "time: sometimes\n"                   // 2
                                       "duraton: 30s\n"                      // 3
                                       "world: map.json\n"                   // 4
                                       "vehicles:\n"                         // 5
                                       "  - id: 5\n"                         // 6
                                       "    start: [0, 1]\n"                 // 7
                                       "    fsm: missing.json\n"             // 8
                                       "  - id: 5\n"                         // 9
                                       "    start: [0, nan, 0]\n"            // 10
                                       "  - id: 300\n"                       // 11
                                       "    camra: cam.yaml\n"               // 12
                                       "routing: {enabled: true, period: 30ms}\n"  // 13
                                       "qos: {vehicleState: {reliable: maybe}}\n"); // 14
    const auto errors = errors_of(file);
    const std::vector<std::string> expected = {
        file + ":3: duraton: unknown key (did you mean 'duration'?); known: name, domain, time, duration, world, lanes, vehicles, routing, qos, record, monitor, parameters, security, hosts, ssh_config, max_clock_offset, discovery, discovery_server, history, controllers, ips, timeouts",
        file + ":1: name: 'bad run': use letters, digits, - and _ only",
        file + ":2: time: 'sometimes': expected real or simulated",
        file + ":1: duration: missing (how long the run lasts, e.g. 30s)",
        file + ":7: vehicles[0].start: expected [x, y, yaw] in metres and radians",
        file + ":8: vehicles[0].fsm: state machine 'missing.json' does not exist (looked for " + (dir.path / "missing.json").string() + ")",
        file + ":9: vehicles[1].id: 5 is given twice (also vehicles[0])",
        file + ":10: vehicles[1].start[1]: 'nan' is not a finite number",
        file + ":12: vehicles[2].camra: unknown key (did you mean 'camera'?); known: id, start, camera, fsm, restart, host, realtime, firmware",
        file + ":11: vehicles[2].id: 300 is out of range (1 to 255)",
        file + ":13: routing.period: must be a multiple of 50ms",
        file + ":13: routing.enabled: central routing needs a lane graph: give lanes",
        file + ":8: vehicles[0].fsm: a car either follows its fsm or central routing, not both",
        file + ":7: vehicles[0].start: with routing the cars are spread over the lanes; leave start out",
        file + ":10: vehicles[1].start: with routing the cars are spread over the lanes; leave start out",
        file + ":14: qos.vehicleState.reliable: expected true or false",
    };
    EXPECT_EQ(errors, expected);
}

TEST(Scenario, InSimulatedTimeACarsCameraAndItsMarkerFinderTickOnTheLabClock)
{
    TempDir dir;
    const std::string bin = fake_bin(dir, {"cpm", "cpm_history", "fsm_node", "aruco_node", "firmware_sim", "vehicle_bridge", "camera_sim"});
    const Scenario gates = load_scenario(labs("gates.yaml"));
    const auto plan = plan_run(gates, {.bin_dir = bin, .run_dir = "/runs/g", .domain = 4, .time = TimeMode::simulated});
    ASSERT_EQ(plan.size(), 7u);
    EXPECT_EQ(plan[4].name, "camera_6");
    EXPECT_EQ(plan[4].argv.back(), "--simulated_time");
    EXPECT_EQ(plan[4].timer, "camera_sim_6");
    EXPECT_EQ(plan[5].name, "aruco_6");
    EXPECT_EQ(plan[5].argv.back(), "--simulated_time");
    EXPECT_EQ(plan[5].timer, "aruco_node_6");
    // In real time the camera and the marker finder take each frame as it comes: no timer for the clock.
    const auto real = plan_run(gates, {.bin_dir = bin, .run_dir = "/runs/g", .domain = 4});
    EXPECT_EQ(real[4].timer, "");
    EXPECT_EQ(real[5].timer, "");
    EXPECT_EQ(std::find(real[5].argv.begin(), real[5].argv.end(), "--simulated_time"), real[5].argv.end());
}

TEST(Scenario, StartsOutsideTheWallsOnAWallOrOnAnotherCarAreRefusedNamingTheCars)
{
    TempDir dir;
    const std::string world = cpm_test::source_dir() + "/scenarios/maps/corridor.json";
    const std::string file = dir.write("starts.yaml", "name: s\nduration: 5s\nworld: " + world +
                                                          "\nvehicles:\n"
                                                          "  - {id: 5, start: [0.0, -0.01, 0]}\n"
                                                          "  - {id: 6, start: [0.1, -0.01, 0]}\n"    // 0.1 m behind a 0.4 m car
                                                          "  - {id: 7, start: [50, 50, 0]}\n"        // far outside the corridor
                                                          "  - {id: 8, start: [3.0, -0.55, 0]}\n"    // across the niche's wall
                                                          "  - {id: 9, start: [4.0, 0.2, 0]}\n");   // clear: no error
    const auto errors = errors_of(file);
    ASSERT_EQ(errors.size(), 3u) << ::testing::PrintToString(errors);
    EXPECT_EQ(errors[0], file + ":6: vehicles[1].start: car 6 at (0.1, -0.01): its body overlaps car 5's (vehicles[0].start) at the start");
    EXPECT_EQ(errors[1].rfind(file + ":7: vehicles[2].start: car 7 at (50, 50) is outside the world's walls (corridor.json)", 0), 0u)
        << errors[1];
    EXPECT_EQ(errors[2], file + ":8: vehicles[3].start: car 8 at (3, -0.55): its body crosses the wall [3.3, -0.85, 3.3, -0.6] at the start");
}

TEST(Scenario, AFileThatIsNotYamlOrNotThereIsNamed)
{
    TempDir dir;
    const std::string broken = dir.write("broken.yaml", "name: x\nvehicles: [\n");
    auto errors = errors_of(broken);
    ASSERT_EQ(errors.size(), 1u);
    EXPECT_EQ(errors[0].rfind(broken + ":3: not YAML", 0), 0u) << errors[0];
    errors = errors_of(dir.path / "none.yaml");
    ASSERT_EQ(errors.size(), 1u);
    EXPECT_EQ(errors[0], (dir.path / "none.yaml").string() + ": cannot open the scenario file: no such file");
}

TEST(Scenario, AMissingProgramIsNamedBeforeAnythingStarts)
{
    TempDir dir;
    const std::string bin = fake_bin(dir, {"cpm", "cpm_history", "firmware_sim", "vehicle_bridge", "camera_sim"});
    const Scenario s = load_scenario(labs("gates.yaml"));
    try {
        (void)plan_run(s, {.bin_dir = bin, .run_dir = "/r"});
        FAIL() << "planned without fsm_node and aruco_node";
    } catch (const ScenarioError& e) {
        ASSERT_EQ(e.errors().size(), 2u) << e.what();
        EXPECT_NE(e.errors()[0].find(bin + "/aruco_node, which does not exist"), std::string::npos) << e.what();
        EXPECT_NE(e.errors()[1].find(bin + "/fsm_node, which does not exist"), std::string::npos) << e.what();
    }
}

TEST(Scenario, RoutingNeedsConsecutiveIdsForItsOneSimulator)
{
    TempDir dir;
    dir.write("lanes.json", "{}");
    const std::string file = dir.write("r.yaml", "name: r\nduration: 10s\nlanes: lanes.json\nrouting: {enabled: true}\n"
                                                 "vehicles:\n  - {id: 1}\n  - {id: 3}\n");
    EXPECT_EQ(errors_of(file), std::vector<std::string>{file + ":6: vehicles: with routing the cars run in one simulator and need "
                                                               "consecutive ids (e.g. 1, 2, 3)"});
}

TEST(Scenario, ASecuredLabRunsEachProcessAsANodeAllowedTheTopicsItUses)
{
    TempDir dir;
    dir.write("map.json", "{\"walls\": []}");
    // What `cpm security init` leaves (the run only checks that they are there).
    fs::create_directories(dir.path / "lab-sec");
    for (const char* f : {"identity_ca.cert.pem", "identity_ca.key.pem", "permissions_ca.cert.pem", "permissions_ca.key.pem", "governance.p7s"})
        dir.write(std::string("lab-sec/") + f, "x");
    const std::string file =
        dir.write("s.yaml", "name: s\nduration: 5s\nworld: map.json\nsecurity: lab-sec\nvehicles: [{id: 2, fsm: map.json}]\n");
    const Scenario s = load_scenario(file);
    EXPECT_EQ(s.security, fs::weakly_canonical(dir.path / "lab-sec").string());
    const auto plan = plan_run(s, {.bin_dir = fake_bin(dir, {"cpm_history", "cpm", "fsm_node", "firmware_sim", "vehicle_bridge"}),
                                   .run_dir = "/runs/s-1", .domain = 3});
    ASSERT_EQ(plan.size(), 4u);
    for (const auto& p : plan) {
        const std::string node = s.security + "/nodes/s-1-" + p.name;
        EXPECT_EQ(p.security_node, node);
        ASSERT_GE(p.argv.size(), 2u);
        EXPECT_EQ(std::vector<std::string>(p.argv.end() - 2, p.argv.end()), (std::vector<std::string>{"--security", node})) << p.name;
    }
    // The simulator and the bridge, each allowed only what it uses.
    EXPECT_EQ(plan[1].name, "sim_2");
    EXPECT_EQ(plan[1].publish, (std::vector<std::string>{"vehicleObservation"}));
    EXPECT_EQ(plan[1].subscribe, (std::vector<std::string>{"vehicleObservation"}));
    EXPECT_EQ(plan[2].name, "bridge_2");
    EXPECT_EQ(plan[2].publish, (std::vector<std::string>{"vehicleState", "rangeSensors"}));
    EXPECT_EQ(plan[2].subscribe, (std::vector<std::string>{"vehicleCommandDirect", "vehicleCommandSpeedCurvature", "vehicleCommandTrajectory",
                                                           "vehicleCommandPathTracking", "stopRequest", "vehicleObservation"}));
    EXPECT_EQ(plan[3].name, "fsm_2");
    EXPECT_EQ(plan[3].publish, (std::vector<std::string>{"vehicleCommandDirect", "fsmStatus", "stopRequest"}));

    // A folder that is not a lab's is named with what to do.
    const auto errors = errors_of(dir.write("bad.yaml", "name: b\nduration: 5s\nworld: map.json\nsecurity: map.json\nvehicles: [{id: 2}]\n"));
    ASSERT_EQ(errors.size(), 1u);
    EXPECT_NE(errors[0].find("bad.yaml:4: security: 'map.json'"), std::string::npos) << errors[0];
    EXPECT_NE(errors[0].find("cpm security init DIR"), std::string::npos) << errors[0];
}

TEST(Scenario, HostsNameEachProcessesComputerAndEveryMistakeInThemIsNamed)
{
    TempDir dir;
    dir.write("map.json", "{\"walls\": []}");
    const std::string bin = fake_bin(dir, {"cpm", "cpm_history", "firmware_sim", "vehicle_bridge"});
    const std::string good = dir.write("hosts.yaml",
                                       "name: h\nduration: 5s\nworld: map.json\n"
                                       "hosts:\n  central: {address: 10.1.0.1}\n  car_a: {address: 10.1.0.2, ssh: pi@10.1.0.2, cpm: /opt/cpm}\n"
                                       "history: {host: central}\n"
                                       "vehicles: [{id: 2, host: car_a}]\n");
    const auto s = load_scenario(good);
    ASSERT_EQ(s.hosts.size(), 2u);
    EXPECT_EQ(s.local_host()->name, "central");
    EXPECT_EQ(s.host("car_a")->cpm, "/opt/cpm");
    RunSettings r{.bin_dir = bin, .run_dir = dir.file("run"), .domain = 3};
    const auto plan = plan_run(s, r);
    for (const auto& p : plan) {
        const bool on_car = p.name == "sim_2" || p.name == "bridge_2";
        EXPECT_EQ(p.host, on_car ? "car_a" : "central") << p.name;
        // Its host's address for DDS, the other host as its peer; the program as installed there.
        const std::string own = on_car ? "10.1.0.2" : "10.1.0.1", other = on_car ? "10.1.0.1" : "10.1.0.2";
        const auto flag = [&](const std::string& name) {
            const auto it = std::find(p.argv.begin(), p.argv.end(), name);
            return it == p.argv.end() || it + 1 == p.argv.end() ? std::string() : *(it + 1);
        };
        EXPECT_EQ(flag("--dds_interface"), own) << p.name;
        EXPECT_EQ(flag("--dds_initial_peer"), other) << p.name;
        if (on_car) {
            EXPECT_EQ(p.argv[0].rfind("/opt/cpm/bin/", 0), 0u) << p.argv[0];
        }
    }

    const auto errors = errors_of(dir.write("bad_hosts.yaml",
                                            "name: h\nduration: 5s\nworld: map.json\n"
                                            "hosts:\n  central: {address: 10.1.0.1}\n  car_a: {adress: 10.1.0.2, ssh: car_a}\n"
                                            "  car_b: {address: ten, ssh: car_b}\n"
                                            "vehicles: [{id: 2, host: car_c}, {id: 3, host: lab}]\n"));
    const std::string file = dir.file("bad_hosts.yaml");
    EXPECT_EQ(errors, (std::vector<std::string>{
                          file + ":6: hosts.car_a.adress: unknown key (did you mean 'address'?); known: address, ssh, cpm",
                          file + ":6: hosts.car_a.address: missing (the IPv4 address its processes use for DDS)",
                          file + ":7: hosts.car_b.address: 'ten' is not an IPv4 address",
                          file + ":8: vehicles[0].host: no host 'car_c' (did you mean 'car_a'?); hosts: central, car_a, car_b",
                          file + ":8: vehicles[1].host: no host 'lab'; hosts: central, car_a, car_b",
                      }));
    const auto no_local = errors_of(dir.write("no_local.yaml", "name: h\nduration: 5s\nworld: map.json\n"
                                                               "hosts: {a: {address: 10.1.0.1, ssh: a}}\nvehicles: [{id: 2}]\n"));
    ASSERT_EQ(no_local.size(), 1u);
    EXPECT_NE(no_local[0].find("hosts: 0 hosts without ssh; exactly one must be the host the run runs on"), std::string::npos) << no_local[0];
}

TEST(Scenario, AMachineThatLooksForGatesOnACarWithoutACameraIsRefused)
{
    TempDir dir;
    const std::string root = cpm_test::source_dir() + "/scenarios/";
    const std::string file = dir.write("blind.yaml", "name: b\nduration: 5s\nworld: " + root + "maps/gates.json\n"
                                                     "vehicles:\n  - {id: 5, start: [0.0, 0.0, 0.3], fsm: " + root + "fsm/gates.json}\n"
                                                     "  - {id: 6, start: [0.0, 0.6, 0.3], fsm: " + root + "fsm/corridor.json}\n");
    const auto errors = errors_of(file);
    ASSERT_EQ(errors.size(), 1u) << ::testing::PrintToString(errors);
    EXPECT_EQ(errors[0], file + ":5: vehicles[0].fsm: its machine works on ArUco markers, but the car has no camera: give it one (camera: FILE)");
    // With its camera it is fine.
    EXPECT_TRUE(errors_of(dir.write("seeing.yaml", "name: b\nduration: 5s\nworld: " + root + "maps/gates.json\n"
                                                   "vehicles:\n  - {id: 5, start: [0.0, 0.0, 0.3], fsm: " + root + "fsm/gates.json, camera: " +
                                                   root + "cameras/sim_640x480.yaml}\n")).empty());
}

TEST(Scenario, AStateMachineThatIncludesOthersGoesToAnotherHostWithThemAsTheyLie)
{
    TempDir dir;
    dir.write("map.json", "{\"walls\": []}");
    // fsm/car.json includes fsm/parts/turn.json, which includes common/stop.json (../../common).
    fs::create_directories(dir.path / "fsm" / "parts");
    fs::create_directories(dir.path / "common");
    dir.write("fsm/car.json", R"({"root": 0, "states": [{"id": 0, "type": "FSMState", "file": "parts/turn.json", "final": true}], "transitions": []})");
    dir.write("fsm/parts/turn.json", R"({"root": 0, "states": [{"id": 0, "type": "FSMState", "file": "../../common/stop.json", "final": true}], "transitions": []})");
    dir.write("common/stop.json", R"({"root": 0, "states": [{"id": 0, "type": "Stop", "final": true}], "transitions": []})");
    const std::string bin = fake_bin(dir, {"cpm", "cpm_history", "firmware_sim", "vehicle_bridge", "fsm_node"});
    const auto s = load_scenario(dir.write("nested.yaml", "name: n\nduration: 5s\nworld: map.json\n"
                                                          "hosts:\n  central: {address: 10.1.0.1}\n  car_a: {address: 10.1.0.2, ssh: car_a, cpm: /opt/cpm}\n"
                                                          "vehicles: [{id: 2, host: car_a, fsm: fsm/car.json}]\n"));
    const auto plan = plan_run(s, RunSettings{.bin_dir = bin, .run_dir = dir.file("run7"), .domain = 3});
    const auto fsm = std::find_if(plan.begin(), plan.end(), [](const ProcessPlan& p) { return p.name == "fsm_2"; });
    ASSERT_NE(fsm, plan.end());
    const auto at = std::find(fsm->argv.begin(), fsm->argv.end(), "--fsm");
    ASSERT_NE(at, fsm->argv.end());
    const std::string given = *(at + 1);  // /tmp/cpm-runs/run7/tree_N/fsm/car.json
    ASSERT_EQ(given.rfind("/tmp/cpm-runs/run7/tree_", 0), 0u) << given;
    const std::string tree = given.substr(0, given.size() - std::string("fsm/car.json").size());
    EXPECT_EQ(given.substr(tree.size()), "fsm/car.json");
    std::map<std::string, std::string> copies(fsm->copies.begin(), fsm->copies.end());
    const std::string root = fs::weakly_canonical(dir.path).string();
    EXPECT_EQ(copies, (std::map<std::string, std::string>{{root + "/fsm/car.json", given},
                                                          {root + "/fsm/parts/turn.json", tree + "fsm/parts/turn.json"},
                                                          {root + "/common/stop.json", tree + "common/stop.json"}}));
}

TEST(Scenario, WithADiscoveryServerItRunsOnItsHostAndEveryProcessIsPointedAtIt)
{
    TempDir dir;
    dir.write("map.json", "{\"walls\": []}");
    const std::string bin = fake_bin(dir, {"cpm", "cpm_history", "firmware_sim", "vehicle_bridge"});
    const std::string hosts = "hosts:\n  central: {address: 10.1.0.1}\n  car_a: {address: 10.1.0.2, ssh: car_a}\n";
    const auto s = load_scenario(dir.write("server.yaml", "name: h\nduration: 5s\nworld: map.json\n" + hosts +
                                                              "discovery: server\ndiscovery_server: car_a\nvehicles: [{id: 2, host: car_a}]\n"));
    ASSERT_TRUE(s.discovery_server);
    EXPECT_EQ(s.discovery_server_locator(), "10.1.0.2:11811");
    const auto plan = plan_run(s, RunSettings{.bin_dir = bin, .run_dir = dir.file("run"), .domain = 3});
    ASSERT_FALSE(plan.empty());
    // The server first (the history needs it), on its host as the system installs it, stopped last.
    EXPECT_EQ(plan[0].name, "discovery_server");
    EXPECT_EQ(plan[0].host, "car_a");
    EXPECT_EQ(plan[0].argv, (std::vector<std::string>{"/usr/bin/fast-discovery-server", "-i", "0", "-l", "10.1.0.2", "-p", "11811"}));
    for (const auto& p : plan) {
        EXPECT_GE(plan[0].stop_order, p.stop_order) << p.name;
        if (p.name == "discovery_server") continue;
        const auto at = std::find(p.argv.begin(), p.argv.end(), "--dds_discovery_server");
        ASSERT_NE(at, p.argv.end()) << p.name;
        EXPECT_EQ(*(at + 1), "10.1.0.2:11811") << p.name;
        EXPECT_EQ(std::find(p.argv.begin(), p.argv.end(), "--dds_initial_peer"), p.argv.end()) << p.name;
    }
    // Default: on the run's own host.
    EXPECT_EQ(load_scenario(dir.write("default.yaml", "name: h\nduration: 5s\nworld: map.json\n" + hosts + "discovery: server\nvehicles: [{id: 2}]\n"))
                  .discovery_server_host, "central");

    const std::string bad = dir.write("bad.yaml", "name: h\nduration: 5s\nworld: map.json\n" + hosts +
                                                      "discovery: sever\ndiscovery_server: car_b\nvehicles: [{id: 2}]\n");
    EXPECT_EQ(errors_of(bad), (std::vector<std::string>{
                                  bad + ":7: discovery: 'sever': expected peers (unicast to every host's address) or server (fast-discovery-server)",
                                  bad + ":8: discovery_server: only with discovery: server",
                              }));
    const std::string alone = dir.write("alone.yaml", "name: h\nduration: 5s\nworld: map.json\ndiscovery: server\nvehicles: [{id: 2}]\n");
    EXPECT_EQ(errors_of(alone), (std::vector<std::string>{alone + ":4: discovery: only for a lab across hosts: name them under hosts:"}));
}

TEST(Scenario, AControllerRunsOnADomainOfItsOwnWithItsMiddlewareAndItsFilesByTheirFullPaths)
{
    TempDir dir;
    dir.write("lanes.json", "{}");
    dir.write("gaps.json", "{}");
    dir.write("ctl.py", "print('hello')\n");
    const std::string file = dir.write("c.yaml", "name: c\ntime: simulated\nduration: 10s\nlanes: lanes.json\ndomain: 30\n"
                                                 "vehicles:\n  - {id: 1}\n  - {id: 2}\n"
                                                 "controllers:\n  - program: ctl.py\n    args: [\"--gaps\", \"gaps.json\"]\n"
                                                 "    vehicles: [1, 2]\n    period: 200ms\n");
    const Scenario s = load_scenario(file);
    ASSERT_EQ(s.controllers.size(), 1u);
    EXPECT_EQ(s.controllers[0].name, "ctl");
    EXPECT_TRUE(s.controllers[0].python());
    const std::string bin = fake_bin(dir, {"cpm_history", "cpm", "hlc_middleware"});
    RunSettings r{.bin_dir = bin, .run_dir = dir.file("run"), .domain = 30, .time = TimeMode::simulated};
    const auto plan = plan_run(s, r);
    auto named = [&](const std::string& n) { return *std::find_if(plan.begin(), plan.end(), [&](const ProcessPlan& p) { return p.name == n; }); };
    const auto middleware = named("hlc_ctl"), controller = named("controller_ctl");
    EXPECT_EQ(middleware.timer, "hlc_middleware_ctl") << "the lab clock waits for it";
    EXPECT_EQ(middleware.argv, (std::vector<std::string>{bin + "/hlc_middleware", "--vehicle_ids", "1,2", "--controller_domain", "31", "--name", "ctl",
                                                         "--period", "200ms", "--dds_domain", "30", "--simulated_time"}));
    EXPECT_EQ(controller.argv, (std::vector<std::string>{"/usr/bin/env", "PYTHONPATH=" + dir.file("python") + ":" + dir.file("lib/python3/dist-packages"),
                                                         "/usr/bin/python3", dir.file("ctl.py"), "--gaps", dir.file("gaps.json"), "--vehicle_ids",
                                                         "1,2", "--dds_domain", "31", "--simulated_time"}));
    EXPECT_LT(controller.stop_order, middleware.stop_order) << "the controller stops before its middleware";
    EXPECT_EQ(named("cars").argv[1], "vehicle") << "the cars are spread over the lanes in one simulator";
    EXPECT_EQ(controller_domains(s, r), (std::map<std::string, int>{{"ctl", 31}}));
    r.controller_domains = {{"ctl", 44}};
    EXPECT_EQ(controller_domains(s, r), (std::map<std::string, int>{{"ctl", 44}})) << "as the run chose it";
}

TEST(Scenario, EveryMistakeInAControllerIsNamedWithItsPath)
{
    TempDir dir;
    dir.write("lanes.json", "{}");
    dir.write("ctl.py", "");
    dir.write("not_executable", "");
    const std::string file = dir.write("c.yaml", "name: c\nduration: 10s\nlanes: lanes.json\ndomain: 30\n"
                                                 "vehicles:\n  - {id: 1}\n  - {id: 2, fsm: x.json}\n"
                                                 "controllers:\n"
                                                 "  - {program: ctl.py, vehicles: [1, 7], period: 5ms, domain: 30}\n"
                                                 "  - {program: not_executable, name: ctl, vehicles: [1], perod: 1s}\n"
                                                 "  - {program: missing.py}\n");
    const auto errors = errors_of(file);
    auto has = [&](const std::string& text) {
        return std::any_of(errors.begin(), errors.end(), [&](const std::string& e) { return e.find(text) != std::string::npos; });
    };
    EXPECT_TRUE(has(file + ":9: controllers[0].vehicles[1]: 7 is no car of vehicles:")) << testing::PrintToString(errors);
    EXPECT_TRUE(has(file + ":9: controllers[0].period: must be whole milliseconds, at least 10ms")) << testing::PrintToString(errors);
    EXPECT_TRUE(has(file + ":9: controllers[0].domain: 30 is the lab's own domain: a controller needs one of its own")) << testing::PrintToString(errors);
    EXPECT_TRUE(has(":10: controllers[1].perod: unknown key (did you mean 'period'?)")) << testing::PrintToString(errors);
    EXPECT_TRUE(has(":10: controllers[1].name: 'ctl' is the name of controllers[0] too")) << testing::PrintToString(errors);
    EXPECT_TRUE(has(":10: controllers[1].vehicles[0]: car 1 is driven by controllers[0] already")) << testing::PrintToString(errors);
    EXPECT_TRUE(has("controllers[1].program: " + dir.file("not_executable") + " is not executable")) << testing::PrintToString(errors);
    EXPECT_TRUE(has(":11: controllers[2].program: controller program 'missing.py' does not exist")) << testing::PrintToString(errors);
    EXPECT_TRUE(has(":11: controllers[2].vehicles: missing")) << testing::PrintToString(errors);
    EXPECT_TRUE(has(":7: vehicles[1].fsm: a car either follows its fsm or controllers, not both")) << testing::PrintToString(errors);
}

TEST(Scenario, InALabAcrossHostsAControllerStaysOnThisHostAndItsMiddlewareJoinsTheLab)
{
    TempDir dir;
    dir.write("lanes.json", "{}");
    const std::string bin = fake_bin(dir, {"cpm", "cpm_history", "hlc_middleware", "hlc_platoon"});
    const std::string file = dir.write("h.yaml", "name: h\nduration: 5s\nlanes: lanes.json\n"
                                                 "hosts:\n  central: {address: 10.1.0.1}\n  car_a: {address: 10.1.0.2, ssh: pi@10.1.0.2, cpm: /opt/cpm}\n"
                                                 "vehicles: [{id: 1, host: car_a}]\n"
                                                 "controllers: [{program: hlc_platoon, vehicles: [1], host: central}]\n");
    const auto plan = plan_run(load_scenario(file), RunSettings{.bin_dir = bin, .run_dir = dir.file("run"), .domain = 3});
    auto argv_of = [&](const std::string& n) {
        return std::find_if(plan.begin(), plan.end(), [&](const ProcessPlan& p) { return p.name == n; })->argv;
    };
    const auto controller = argv_of("controller_hlc_platoon"), middleware = argv_of("hlc_hlc_platoon");
    EXPECT_EQ(controller[0], bin + "/hlc_platoon") << "cpm's program by its name";
    EXPECT_EQ(std::count(controller.begin(), controller.end(), "--dds_interface"), 0) << "its own domain: this host only";
    EXPECT_EQ(std::count(middleware.begin(), middleware.end(), "--dds_interface"), 1) << "the lab's domain: across the hosts";
}

TEST(Scenario, AControllerOnAnotherHostRunsThereWithItsScriptCopiedAndFindsCpmThere)
{
    TempDir dir;
    dir.write("lanes.json", "{}");
    dir.write("ctl.py", "");
    dir.write("ctl", "");
    const std::string bin = fake_bin(dir, {"cpm", "cpm_history", "hlc_middleware"});
    const std::string hosts = "hosts:\n  central: {address: 10.1.0.1}\n  car_a: {address: 10.1.0.2, ssh: pi@10.1.0.2, cpm: /opt/cpm}\n";
    const std::string file = dir.write("h.yaml", "name: h\nduration: 5s\nlanes: lanes.json\n" + hosts + "vehicles: [{id: 1, host: car_a}]\n"
                                                 "controllers: [{program: ctl.py, vehicles: [1], host: car_a}]\n");
    const RunSettings r{.bin_dir = bin, .run_dir = dir.file("run"), .domain = 3};
    const auto plan = plan_run(load_scenario(file), r);
    auto named = [&](const std::string& n) { return *std::find_if(plan.begin(), plan.end(), [&](const ProcessPlan& p) { return p.name == n; }); };
    const auto controller = named("controller_ctl"), middleware = named("hlc_ctl");
    EXPECT_EQ(controller.host, "car_a");
    EXPECT_EQ(middleware.host, "car_a");
    EXPECT_EQ(controller.argv[1], "PYTHONPATH=/opt/cpm/python:/opt/cpm/lib/python3/dist-packages") << "cpm's Python package there";
    EXPECT_EQ(controller.argv[2], "/usr/bin/python3");
    EXPECT_EQ(controller.argv[3], remote_run_dir(r) + "/ctl.py") << "the script copied there";
    ASSERT_EQ(controller.copies.size(), 1u);
    EXPECT_EQ(controller.copies[0], std::make_pair(dir.file("ctl.py"), remote_run_dir(r) + "/ctl.py"));
    EXPECT_EQ(std::count(controller.argv.begin(), controller.argv.end(), "--dds_interface"), 0);
    EXPECT_EQ(middleware.argv[0], "/opt/cpm/bin/hlc_middleware");
    EXPECT_EQ(std::count(middleware.argv.begin(), middleware.argv.end(), "10.1.0.2"), 1) << "its host's address for the lab";
    ::chmod(dir.file("ctl").c_str(), 0755);
    const std::string other = dir.write("o.yaml", "name: o\nduration: 5s\nlanes: lanes.json\n" + hosts + "vehicles: [{id: 1, host: car_a}]\n"
                                                  "controllers: [{program: ctl, vehicles: [1], host: car_a}]\n");
    EXPECT_EQ(errors_of(other), std::vector<std::string>{other + ":8: controllers[0].program: on another host a controller is one of cpm's programs "
                                                                 "or a Python script (copied there)"});
}

TEST(Scenario, ACarMarkedRealtimeRunsEachOfItsProcessesWithTheFlagAndAWrongValueIsNamed)
{
    TempDir dir;
    dir.write("map.json", "{\"walls\": []}");
    dir.write("cam.yaml", "");
    dir.write("m.json", "{}");
    const std::string bin = fake_bin(dir, {"cpm_history", "cpm", "firmware_sim", "vehicle_bridge", "camera_sim", "aruco_node", "fsm_node"});
    const Scenario s = load_scenario(dir.write("r.yaml", "name: r\nduration: 5s\nworld: map.json\n"
                                                         "vehicles:\n  - {id: 2, realtime: true, camera: cam.yaml}\n"
                                                         "  - {id: 3, realtime: required, start: [1, 0, 0]}\n  - {id: 4, start: [2, 0, 0]}\n"));
    EXPECT_EQ(s.vehicles[0].realtime, cpm::Realtime::on);
    EXPECT_EQ(s.vehicles[1].realtime, cpm::Realtime::required);
    EXPECT_EQ(s.vehicles[2].realtime, cpm::Realtime::off);
    std::map<std::string, std::string> flag_of;  // process -> its --realtime flag, "" without
    for (const auto& p : plan_run(s, {.bin_dir = bin, .run_dir = "/runs/r", .domain = 3})) {
        for (const auto& a : p.argv) {
            if (a.rfind("--realtime", 0) == 0) flag_of[p.name] += a;
        }
        flag_of.try_emplace(p.name, "");
    }
    EXPECT_EQ(flag_of, (std::map<std::string, std::string>{{"cpm_history", ""},
                                                           {"sim_2", "--realtime"},
                                                           {"bridge_2", "--realtime"},
                                                           {"camera_2", "--realtime"},
                                                           {"aruco_2", "--realtime"},
                                                           {"sim_3", "--realtime=required"},
                                                           {"bridge_3", "--realtime=required"},
                                                           {"sim_4", ""},
                                                           {"bridge_4", ""}}));
    const std::string bad = dir.write("b.yaml", "name: b\nduration: 5s\nworld: map.json\nvehicles:\n  - {id: 2, realtime: always}\n"
                                                "routing: {realtime: 2}\n");
    const auto errors = errors_of(bad);
    EXPECT_NE(testing::PrintToString(errors).find(bad + ":5: vehicles[0].realtime: expected true, false or required"), std::string::npos)
        << testing::PrintToString(errors);
    EXPECT_NE(testing::PrintToString(errors).find(bad + ":6: routing.realtime: expected true, false or required"), std::string::npos)
        << testing::PrintToString(errors);
}

TEST(Scenario, ACarOnItsAvrFirmwareRunsFirmwareHilAndAWrongValueOrAMixOnLanesIsNamed)
{
    TempDir dir;
    dir.write("map.json", "{\"walls\": []}");
    const std::string bin = fake_bin(dir, {"cpm_history", "cpm", "firmware_sim", "firmware_hil", "vehicle_bridge"});
    const Scenario s = load_scenario(dir.write("f.yaml", "name: f\nduration: 5s\nworld: map.json\n"
                                                         "vehicles:\n  - {id: 2, firmware: avr}\n  - {id: 3, firmware: sim, start: [1, 0, 0]}\n"
                                                         "  - {id: 4, start: [2, 0, 0]}\n"));
    EXPECT_TRUE(s.vehicles[0].avr);
    EXPECT_FALSE(s.vehicles[1].avr);
    EXPECT_FALSE(s.vehicles[2].avr);
    std::map<std::string, std::string> program_of;
    for (const auto& p : plan_run(s, {.bin_dir = bin, .run_dir = "/runs/f", .domain = 3})) {
        program_of[p.name] = fs::path(p.argv.at(0)).filename().string();
    }
    EXPECT_EQ(program_of["sim_2"], "firmware_hil");
    EXPECT_EQ(program_of["sim_3"], "firmware_sim");
    EXPECT_EQ(program_of["sim_4"], "firmware_sim");
    EXPECT_EQ(program_of["bridge_2"], "vehicle_bridge") << "the bridge is the same for either";

    const std::string bad = dir.write("b.yaml", "name: b\nduration: 5s\nworld: map.json\nvehicles:\n  - {id: 2, firmware: arm}\n");
    EXPECT_EQ(errors_of(bad),
              std::vector<std::string>{bad + ":5: vehicles[0].firmware: expected sim (firmware_sim) or avr (the car's AVR firmware under firmware_hil)"});
    dir.write("lanes.json", "{}");
    const std::string mixed = dir.write("m.yaml", "name: m\nduration: 5s\nworld: map.json\nlanes: lanes.json\nrouting: {enabled: true}\n"
                                                  "vehicles:\n  - {id: 2, firmware: avr}\n  - {id: 3}\n");
    EXPECT_NE(testing::PrintToString(errors_of(mixed))
                  .find(mixed + ":8: vehicles[1].firmware: cars on lanes share one simulation: give every car the same firmware (vehicles[0] has avr)"),
              std::string::npos)
        << testing::PrintToString(errors_of(mixed));
}
