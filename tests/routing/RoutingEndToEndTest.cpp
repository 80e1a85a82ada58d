// Real processes: simulated cars (firmware_sim + vehicle_bridge behind ptys) driven by
// central_routing over DDS, judged by the simulator's true poses (vehicleObservation); a car
// off the graph, a car that goes silent, and bad input.
#include "BodyGap.hpp"

#include <cpm/Participant.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/routing/TrafficWatch.hpp>
#include <cpm/timer_ids.hpp>

#include <cpm_test/Dds.hpp>
#include <cpm_test/Isolation.hpp>
#include <cpm_test/Process.hpp>
#include <cpm_test/SourceDir.hpp>

#include <VehicleCommandTrajectory.h>
#include <VehicleObservation.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <thread>

using namespace std::chrono_literals;
using cpm_test::built_program;
using cpm_test::Process;

namespace {

const std::string kRoot = cpm_test::source_dir();
const std::string kLanes = kRoot + "/scenarios/lanes/intersection.json";

/// Every observation of every car, collected while `run` lasts.
std::map<int, std::vector<VehicleObservation>> watch(cpm::ReaderAbstract<VehicleObservation>& reader, std::chrono::seconds run)
{
    std::map<int, std::vector<VehicleObservation>> seen;
    const auto end = std::chrono::steady_clock::now() + run;
    while (std::chrono::steady_clock::now() < end) {
        for (auto& o : reader.take()) seen[o.vehicle_id()].push_back(o);
        std::this_thread::sleep_for(20ms);
    }
    return seen;
}

double path_length(const std::vector<VehicleObservation>& track)
{
    double d = 0;
    for (size_t i = 1; i < track.size(); ++i) {
        d += std::hypot(track[i].pose().x() - track[i - 1].pose().x(), track[i].pose().y() - track[i - 1].pose().y());
    }
    return d;
}

std::string log_text(const Process& p) { return p.output() + p.errors(); }

/// The tests' own referee of the bodies' gap (not the planner's): each car's pose against every
/// other car's newest, in the order of their stamps.
double referee_gap(std::vector<VehicleObservation> all)
{
    std::stable_sort(all.begin(), all.end(), [](const auto& a, const auto& b) {
        return a.header().create_stamp().nanoseconds() < b.header().create_stamp().nanoseconds();
    });
    const cpm::routing::Footprint f;
    std::map<int, cpm::routing::Pose> newest;
    double gap = std::numeric_limits<double>::infinity();
    for (const auto& o : all) {
        const cpm::routing::Pose p{o.pose().x(), o.pose().y(), o.pose().yaw()};
        for (const auto& [id, q] : newest) {
            if (id != o.vehicle_id()) gap = routing_test::least_gap(f, p, q, gap);
        }
        newest[o.vehicle_id()] = p;
    }
    return gap;
}

}  // namespace

TEST(RoutingEndToEnd, EightCarsDriveTwoSimulatedMinutesWithoutTouchingAndNoneStandsLong)
{
    // The whole lab in simulated time: the cars (one simulator, one bridge process), the
    // planner and the clock that steps them, 120 s of lab time as fast as the machine computes.
    cpm::Participant participant(cpm_test::isolated_options());
    cpm::ReaderAbstract<VehicleObservation> observations(participant, "vehicleObservation", {.keep_all = true});
    cpm::ReaderAbstract<VehicleCommandTrajectory> plans(participant, "vehicleCommandTrajectory", {.keep_all = true});
    Process cars({built_program("cpm"), "vehicle", "sim", "--id", "1", "--count", "8", "--lanes", kLanes, "--simulated_time"});
    Process routing({built_program("central_routing"), "--vehicle_ids", "1,2,3,4,5,6,7,8", "--lanes", kLanes, "--simulated_time"});
    Process clock({built_program("cpm"), "lab", "clock", "--nodes", "firmware_sim_1,vehicle_bridge_1,central_routing", "--simulated",
                   "--until", "120s"});
    std::map<int, std::vector<VehicleObservation>> seen;
    std::vector<VehicleCommandTrajectory> sent;
    const auto take_all = [&] {
        for (auto& o : observations.take()) seen[o.vehicle_id()].push_back(o);
        for (auto& p : plans.take()) sent.push_back(std::move(p));
    };
    const auto give_up = std::chrono::steady_clock::now() + 150s;
    int clock_exit = -1;
    while ((clock_exit = clock.wait(20ms)) == -1 && std::chrono::steady_clock::now() < give_up) take_all();
    ASSERT_EQ(clock_exit, 0) << clock.output() << clock.errors();
    std::this_thread::sleep_for(500ms);
    take_all();
    // The clock's stop ends every timer: the planner and the cars end by themselves.
    ASSERT_EQ(routing.wait(10s), 0) << log_text(routing);
    EXPECT_EQ(cars.wait(15s), 0) << log_text(cars);
    std::printf("%s", clock.output().c_str());

    ASSERT_EQ(seen.size(), 8u) << log_text(cars);
    // The planner plans in the cars' step (it takes no step of its own on the clock), from the
    // cars' states of the step before, and its plans count from the cars' next step: never read
    // in the step that made them, where the cars would see them or not as threads happened to run.
    EXPECT_GT(sent.size(), 8u * 250u) << "a plan for each car every 400 ms";
    for (const auto& p : sent) {
        const uint64_t made = p.header().create_stamp().nanoseconds();
        ASSERT_EQ(made % 20'000'000, cpm::timer_ids::kSimulatedCarOffset_ns) << "vehicle " << int(p.vehicle_id()) << "'s plan of " << made;
        ASSERT_EQ(p.header().valid_after_stamp().nanoseconds(), made + 1) << "vehicle " << int(p.vehicle_id()) << "'s plan of " << made;
    }
    // Every pose in the order it was taken: bodies compared with the others' newest poses
    // (at most 40 ms old), distance and standstills per car.
    std::vector<VehicleObservation> all;
    for (const auto& [id, track] : seen) {
        EXPECT_GT(track.size(), 5000u) << "vehicle " << id << ": 50 Hz for two minutes";
        // Lab time: the stamps span the two simulated minutes.
        EXPECT_GT(track.back().header().create_stamp().nanoseconds(), 119'000'000'000ull) << "vehicle " << id;
        all.insert(all.end(), track.begin(), track.end());
    }
    std::stable_sort(all.begin(), all.end(), [](const auto& a, const auto& b) {
        return a.header().create_stamp().nanoseconds() < b.header().create_stamp().nanoseconds();
    });
    cpm::routing::TrafficWatch watch;
    for (const auto& o : all) watch.add(o.vehicle_id(), o.header().create_stamp().nanoseconds(), {o.pose().x(), o.pose().y(), o.pose().yaw()});
    EXPECT_EQ(watch.overlaps(), 0u) << watch.report();
    EXPECT_GT(watch.min_distance(), 0.0) << watch.report();
    // The tests' own referee of the bodies' gap (not the planner's).
    const double gap = referee_gap(all);
    EXPECT_GT(gap, 0.0) << "two bodies touched (the tests' referee)";
    EXPECT_NEAR(gap, watch.min_distance(), 0.0005);
    for (const auto& [id, car] : watch.cars()) {
        EXPECT_GE(car.distance, 20.0) << "vehicle " << id;
        EXPECT_LE(car.longest_standstill, 10.0) << "vehicle " << id;
    }
    std::printf("%s", watch.report().c_str());
}

TEST(RoutingEndToEnd, ACarOnNoLaneIsLoggedWithItsPoseAndTheOthersAreServed)
{
    cpm::Participant participant(cpm_test::isolated_options());
    cpm::ReaderAbstract<VehicleObservation> observations(participant, "vehicleObservation", {.keep_all = true});
    Process on_lane({built_program("cpm"), "vehicle", "sim", "--id", "1", "--lanes", kLanes});
    Process off_lane({built_program("cpm"), "vehicle", "sim", "--id", "2", "--start", "8,8,0"});
    Process routing({built_program("central_routing"), "--vehicle_ids", "1,2", "--lanes", kLanes, "--no-wait-for-start"});
    const auto seen = watch(observations, 12s);
    EXPECT_TRUE(cpm_test::wait_until([&] {
        const std::string log = log_text(routing);
        const auto at = log.find("vehicle 2 at x 8.000 y 8.000 yaw");
        return at != std::string::npos && log.find("is on no lane", at) != std::string::npos;
    }, 5s)) << log_text(routing);
    ASSERT_TRUE(seen.count(1));
    EXPECT_GT(path_length(seen.at(1)), 3.0);  // car 1 drives all the same
    routing.kill(SIGINT);
    EXPECT_EQ(routing.wait(10s), 0) << log_text(routing);
}

TEST(RoutingEndToEnd, ACarThatGoesSilentIsDroppedAndTakenBackWhenItReturns)
{
    Process cars({built_program("cpm"), "vehicle", "sim", "--id", "3", "--lanes", kLanes});
    Process routing({built_program("central_routing"), "--vehicle_ids", "3", "--lanes", kLanes, "--no-wait-for-start"});
    ASSERT_TRUE(cpm_test::wait_until([&] { return log_text(routing).find("vehicle 3 taken into planning") != std::string::npos; }, 15s))
        << log_text(routing);
    cars.kill(SIGSTOP);  // the simulator and bridge freeze: no more vehicleState
    const bool dropped = cpm_test::wait_until([&] { return log_text(routing).find("vehicle 3 dropped from planning") != std::string::npos; }, 5s);
    cars.kill(SIGCONT);
    EXPECT_TRUE(dropped) << log_text(routing);
    EXPECT_TRUE(cpm_test::wait_until([&] {
        const std::string log = log_text(routing);
        const auto drop = log.find("dropped from planning");
        return drop != std::string::npos && log.find("vehicle 3 is back: taken into planning again", drop) != std::string::npos;
    }, 10s)) << log_text(routing);
    routing.kill(SIGINT);
    EXPECT_EQ(routing.wait(10s), 0) << log_text(routing);
}

TEST(RoutingEndToEnd, BadFilesAndFlagsAreNamedAndExitNonZero)
{
    const auto dir = std::filesystem::temp_directory_path() / ("cpm_routing_e2e_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir);
    const std::string bad = (dir / "bad_lanes.json").string();
    std::ofstream(bad) << R"({"lane_width": 0.3, "nodes": [{"id": 1, "x": 0, "y": 0, "yaw": 0}],
                            "edges": [{"from": 1, "to": 7, "points": [[0, 0], [0.04, 0]]}]})";
    struct Case
    {
        std::vector<std::string> argv;
        std::string says;
    };
    const std::vector<Case> cases{
        {{built_program("central_routing"), "--vehicle_ids", "1", "--lanes", bad}, "$.edges[0].to: node 7 does not exist"},
        {{built_program("central_routing"), "--vehicle_ids", "1", "--lanes", kLanes, "--period", "30ms"}, "--period 30ms"},
        {{built_program("central_routing"), "--vehicle_ids", "1,0", "--lanes", kLanes}, "--vehicle_ids"},
        {{built_program("central_routing"), "--lanes", kLanes}, "--vehicle_ids is required"},
        {{built_program("central_routing"), "--vehicle_ids", "1", "--lanes", kLanes, "--mode", "fastest"}, "--mode fastest"},
        {{built_program("cpm"), "routing", "check", bad}, "$.edges[0].to: node 7 does not exist"},
        {{built_program("cpm"), "routing", "render", kLanes, "--out", (dir / "map.gif").string()}, "must end in .svg or .png"},
        {{built_program("cpm"), "routing", "simulate", "--lanes", kLanes, "--vehicles", "500", "--duration", "1s"}, "--vehicles"},
        {{built_program("cpm"), "routing", "simulate", "--lanes", kLanes, "--vehicles", "80", "--duration", "1s"}, "cars fit on this lane graph"},
        {{built_program("cpm"), "vehicle", "sim", "--id", "1", "--lanes", kLanes, "--start", "0,0,0"}, "--start or --lanes"},
    };
    for (const auto& c : cases) {
        Process p(c.argv);
        const int code = p.wait(20s);
        std::string line;
        for (const auto& a : c.argv) line += a + " ";
        EXPECT_NE(code, 0) << line;
        EXPECT_NE(log_text(p).find(c.says), std::string::npos) << line << "\n" << log_text(p);
    }
    std::filesystem::remove_all(dir);
}

TEST(RoutingEndToEnd, CheckAndRenderTheLabMap)
{
    const auto png = std::filesystem::temp_directory_path() / ("cpm_routing_map_" + std::to_string(::getpid()) + ".svg");
    Process check({built_program("cpm"), "routing", "check", kLanes});
    ASSERT_EQ(check.wait(20s), 0) << log_text(check);
    EXPECT_NE(check.output().find("ok (32 nodes, 38 edges"), std::string::npos) << check.output();
    Process render({built_program("cpm"), "routing", "render", kLanes, "--out", png.string()});
    ASSERT_EQ(render.wait(20s), 0) << log_text(render);
    std::ifstream in(png);
    const std::string svg((std::istreambuf_iterator<char>(in)), {});
    EXPECT_NE(svg.find("<svg"), std::string::npos);
    EXPECT_NE(svg.find(">31</text>"), std::string::npos);  // node ids are drawn
    EXPECT_NE(svg.find("#e4572e"), std::string::npos);     // and the conflict zones
    std::filesystem::remove(png);
}

TEST(RoutingEndToEnd, EightCarsPlacedOnlyByTheOverheadCameraDriveWithoutTouchingAndItsErrorStaysWithin2Cm)
{
    // scenarios/labs/ips.yaml: the cars' vehicleObservation comes from ips_node alone (the
    // overhead camera's frames); the simulator's truth is on a topic of its own, which the test
    // reads (joining once the run has started: the run refuses a domain somebody is on).
    const auto dir = std::filesystem::temp_directory_path() / ("cpm_ips_e2e_" + std::to_string(::getpid()));
    const std::string out = (dir / "run").string();
    std::filesystem::remove_all(dir);
    Process run({built_program("cpm"), "lab", "run", kRoot + "/scenarios/labs/ips.yaml", "--duration", "20s", "--out", out, "--monitor", "off"});
    ASSERT_TRUE(cpm_test::wait_until([&] { return run.errors().find("processes on domain") != std::string::npos; }, 60s)) << run.errors();
    cpm::Participant participant(cpm_test::isolated_options());
    cpm::ReaderAbstract<VehicleObservation> truth(participant, "vehicleObservationTruth", {.keep_all = true});
    std::vector<VehicleObservation> all;
    int exit = -1;
    const auto give_up = std::chrono::steady_clock::now() + 300s;
    while ((exit = run.wait(20ms)) == -1 && std::chrono::steady_clock::now() < give_up) {
        for (auto& o : truth.take()) all.push_back(o);
    }
    ASSERT_EQ(exit, 0) << run.output() << run.errors();
    std::ifstream in(out + "/summary.json");
    const auto summary = nlohmann::json::parse(in);
    EXPECT_EQ(summary["ok"], true) << summary.dump(2);
    const auto& cars = summary["report"]["cars"];
    ASSERT_EQ(cars.size(), 8u) << summary.dump(2);
    for (const auto& [id, car] : cars.items()) {
        EXPECT_GE(car["driven_m"].get<double>(), 5.0) << "car " << id << " drives";
        EXPECT_GE(car["ips_samples"].get<int>(), 900) << "car " << id << ": seen in nearly every one of 1000 frames";
        EXPECT_LE(car["ips_error_m_p99"].get<double>(), 0.02) << "car " << id;
        std::printf("car %s: driven %.1f m, IPS error p50 %.2f mm, p99 %.2f mm, yaw p99 %.2f°\n", id.c_str(), car["driven_m"].get<double>(),
                    car["ips_error_m_p50"].get<double>() * 1000, car["ips_error_m_p99"].get<double>() * 1000,
                    car["ips_yaw_error_deg_p99"].get<double>());
    }
    std::ifstream ips_log(out + "/ips.log");
    const std::string ips_text((std::istreambuf_iterator<char>(ips_log)), std::istreambuf_iterator<char>());
    EXPECT_NE(ips_text.find("\"unknown_markers\": 0, \"seen_twice\": 0, \"misfits\": 0, \"moved_frames\": 0"), std::string::npos) << ips_text;
    // The bodies by the simulator's truth, as the test's own referee sees them.
    ASSERT_GT(all.size(), 8u * 500) << "the truth of most of the run";
    const double gap = referee_gap(all);
    EXPECT_GT(gap, 0.0) << "two bodies touched (the tests' referee)";
    std::printf("smallest gap between two bodies: %.3f m over %zu true poses\n", gap, all.size());
    std::filesystem::remove_all(dir);
}
