// The lane graph (loading, checks, geometry), conflict zones and the planner, in-process.
#include <cpm/Error.hpp>
#include <cpm/routing/Simulate.hpp>

#include "BodyGap.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <cpm_test/SourceDir.hpp>

using namespace cpm::routing;

namespace {

const std::string kRoot = cpm_test::source_dir();
const std::string kIntersection = kRoot + "/scenarios/lanes/intersection.json";
const std::string kRing = kRoot + "/scenarios/lanes/ring.json";

bool has_error(const GraphLoad& loaded, const std::string& part)
{
    for (const auto& e : loaded.errors) {
        if (e.text().find(part) != std::string::npos) return true;
    }
    return false;
}

std::string all_errors(const GraphLoad& loaded)
{
    std::string all;
    for (const auto& e : loaded.errors) all += e.text() + "\n";
    return all;
}

/// A straight edge's points from (x0, y0) to (x1, y1), `step` apart.
std::string points(double x0, double y0, double x1, double y1, double step = 0.04)
{
    const int n = int(std::ceil(std::hypot(x1 - x0, y1 - y0) / step));
    std::string out = "[";
    for (int i = 0; i <= n; ++i) {
        char p[64];
        std::snprintf(p, sizeof p, "%s[%.4f, %.4f]", i ? ", " : "", x0 + (x1 - x0) * i / n, y0 + (y1 - y0) * i / n);
        out += p;
    }
    return out + "]";
}

}  // namespace

TEST(LaneGraph, TheLabMapsLoadWithTheirConflictZones)
{
    const auto graph = load_lane_graph_or_throw(kIntersection);
    for (const auto& n : graph.nodes) {  // about 4.5 x 4 m
        EXPECT_GE(n.p.x(), 0.0);
        EXPECT_LE(n.p.x(), 4.5);
        EXPECT_GE(n.p.y(), 0.0);
        EXPECT_LE(n.p.y(), 4.0);
    }
    const ConflictTable table(graph, {});
    // A central four-way intersection and at least four more zones.
    ASSERT_GE(table.zones().size(), 5u);
    const auto& centre = table.zones()[central_zone(table)].centre;
    EXPECT_NEAR(centre.x(), 2.25, 0.1);
    EXPECT_NEAR(centre.y(), 2.0, 0.1);

    const auto ring = load_lane_graph_or_throw(kRing);
    const ConflictTable ring_table(ring, {});
    EXPECT_EQ(ring_table.zones().size(), 0u);  // one loop: nothing crosses
    EXPECT_EQ(ring.edges.size(), ring.nodes.size());
}

TEST(LaneGraph, EveryErrorIsReportedAtOnceWithItsJsonPath)
{
    const std::string text = R"({"lane_width": 0.3, "colour": 1,
        "nodes": [{"id": 1, "x": 0, "y": 0, "yaw": 0}, {"id": 2, "x": 1, "y": 0, "yaw": 0, "z": 0}],
        "edges": [{"from": 1, "to": 99, "points": )" +
                             points(0, 0, 1, 0) + R"(},
                  {"from": 2, "to": 1, "points": [[1.0, 0.02], [0.96, 0.0], [0.88, 0.0], [0.0, 0.0]]}]})";
    const auto loaded = parse_lane_graph(text, "bad.json");
    EXPECT_FALSE(loaded.ok());
    EXPECT_TRUE(has_error(loaded, "bad.json: $.colour: unknown key")) << all_errors(loaded);
    EXPECT_TRUE(has_error(loaded, "bad.json: $.nodes[1].z: unknown key")) << all_errors(loaded);
    EXPECT_TRUE(has_error(loaded, "bad.json: $.edges[0].to: node 99 does not exist")) << all_errors(loaded);
    EXPECT_TRUE(has_error(loaded, "bad.json: $.edges[1].points[0]: starts 0.020 m from its node 2")) << all_errors(loaded);
    EXPECT_TRUE(has_error(loaded, "bad.json: $.edges[1].points[2]: 0.080 m from the point before it")) << all_errors(loaded);
    EXPECT_TRUE(has_error(loaded, "bad.json: $.edges[1].points[3]: 0.880 m from the point before it")) << all_errors(loaded);
    EXPECT_EQ(loaded.errors.size(), 6u) << all_errors(loaded);
}

TEST(LaneGraph, ANodeWithNoWayOutAndAnEdgeOnNoCycleAreNamed)
{
    // 1 -> 2 -> 1 is a loop; 2 -> 3 leads to a dead end.
    const std::string text = R"({"lane_width": 0.3,
        "nodes": [{"id": 1, "x": 0, "y": 0, "yaw": 0}, {"id": 2, "x": 1, "y": 0, "yaw": 0}, {"id": 3, "x": 1, "y": 1, "yaw": 1.57}],
        "edges": [{"from": 1, "to": 2, "points": )" +
                             points(0, 0, 1, 0) + R"(}, {"from": 2, "to": 1, "points": )" + points(1, 0, 0, 0) +
                             R"(}, {"from": 2, "to": 3, "points": )" + points(1, 0, 1, 1) + R"(}]})";
    const auto loaded = parse_lane_graph(text, "dead_end.json");
    EXPECT_TRUE(has_error(loaded, "dead_end.json: $.nodes[2]: node 3 has no way out")) << all_errors(loaded);
    EXPECT_TRUE(has_error(loaded, "dead_end.json: $.edges[2]: edge 2 -> 3 lies on no cycle")) << all_errors(loaded);
    EXPECT_EQ(loaded.errors.size(), 2u) << all_errors(loaded);
}

TEST(LaneGraph, AFileThatIsNotJsonOrNotThereIsNamed)
{
    EXPECT_TRUE(has_error(parse_lane_graph("{\"nodes\": [", "cut.json"), "cut.json: not valid JSON"));
    const auto missing = load_lane_graph("/nonexistent/lanes.json");
    ASSERT_FALSE(missing.ok());
    EXPECT_NE(missing.errors[0].text().find("/nonexistent/lanes.json"), std::string::npos) << missing.errors[0].text();
    EXPECT_THROW(load_lane_graph_or_throw("/nonexistent/lanes.json"), cpm::Error);
}

TEST(LaneGraph, PoseAtProjectionAndShortestPath)
{
    const auto graph = load_lane_graph_or_throw(kRing);
    // The ring's first edge is its bottom straight, driven in +x.
    const auto& e = graph.edges[0];
    const auto mid = graph.pose_at(0, e.length() / 2);
    EXPECT_NEAR(mid.y, e.points.front().y(), 1e-9);
    EXPECT_NEAR(mid.x, (e.points.front().x() + e.points.back().x()) / 2, 1e-6);
    EXPECT_NEAR(mid.yaw, 0.0, 1e-9);
    // A pose 0.1 m beside the lane, heading along it, projects onto it at the same s.
    auto p = graph.project({mid.x, mid.y + 0.1, 0.1});
    ASSERT_TRUE(p.has_value());
    EXPECT_EQ(p->edge, 0u);
    EXPECT_NEAR(p->s, e.length() / 2, 1e-6);
    EXPECT_NEAR(p->distance, 0.1, 1e-9);
    EXPECT_FALSE(graph.project({mid.x, mid.y, M_PI}).has_value());        // against the lane
    EXPECT_FALSE(graph.project({mid.x, mid.y + 0.5, 0.0}).has_value());   // off it
    // The shortest way from the first edge to the node it started from: round the loop.
    const auto path = graph.shortest_path(0, graph.edges[0].from);
    ASSERT_EQ(path.size(), graph.edges.size());
    for (size_t i = 1; i < path.size(); ++i) EXPECT_EQ(graph.edges[path[i - 1]].to, graph.edges[path[i]].from);
}

TEST(Footprint, DistanceBetweenBodies)
{
    const Footprint f;  // 0.40 x 0.20, rear axle 0.07 from the back
    EXPECT_NEAR(footprint_distance(f, {0, 0, 0}, {0, 0.30, 0}), 0.10, 1e-9);  // side by side
    EXPECT_NEAR(footprint_distance(f, {0, 0, 0}, {0.50, 0, 0}), 0.10, 1e-9);  // nose to tail
    EXPECT_EQ(footprint_distance(f, {0, 0, 0}, {0.1, 0.05, 0.3}), 0.0);      // overlapping
    // Crossing like a plus, no corner of either inside the other: still an overlap.
    EXPECT_EQ(footprint_distance(f, {-0.13, 0, 0}, {0, -0.13, M_PI / 2}), 0.0);
}

TEST(Footprint, TheTestsRefereeAndTheFootprintDistanceAgreeOnHandComputedCases)
{
    const Footprint f;  // body from x = -0.07 to 0.33, y = -0.1 to 0.1 about a car at the origin facing +x
    struct Case
    {
        const char* what;
        Pose a, b;
        double gap;  // by hand
    };
    const double c = std::cos(M_PI / 4), sn = std::sin(M_PI / 4);
    // A corner of b (along -0.07, across -0.1) 3 cm ahead of and 4 cm beside a's front-left corner (0.33, 0.1).
    const Pose corner_to_corner{0.36 + 0.07 * c - 0.1 * sn, 0.14 + 0.07 * sn + 0.1 * c, M_PI / 4};
    const Case cases[] = {
        {"turned 90 degrees, 7 cm ahead of a's nose", {0, 0, 0}, {0.5, 0, M_PI / 2}, 0.07},
        {"turned 45 degrees, corner to corner 5 cm", {0, 0, 0}, corner_to_corner, 0.05},
        {"side by side, 1 mm apart", {0, 0, 0}, {0, 0.201, 0}, 0.001},
        {"the same, turned together by 30 degrees", {1, 1, M_PI / 6}, {1 - 0.201 * std::sin(M_PI / 6), 1 + 0.201 * std::cos(M_PI / 6), M_PI / 6}, 0.001},
        {"facing each other, nose to nose 2 cm", {0, 0, 0}, {0.68, 0, M_PI}, 0.02},
        {"crossing like a plus", {-0.13, 0, 0}, {0, -0.13, M_PI / 2}, 0.0},
        {"overlapping by 1 mm", {0, 0, 0}, {0, 0.199, 0}, 0.0},
    };
    for (const auto& k : cases) {
        EXPECT_NEAR(routing_test::body_gap(f, k.a, k.b), k.gap, 0.0005) << k.what;
        EXPECT_NEAR(footprint_distance(f, k.a, k.b), k.gap, 1e-9) << k.what;
    }
}

TEST(Planner, TheSameSeedGivesByteIdenticalTrajectories)
{
    const auto graph = load_lane_graph_or_throw(kIntersection);
    auto run = [&](uint64_t seed) {
        PlannerOptions o;
        o.seed = seed;
        Planner planner(graph, o);
        const auto starts = spread_cars(planner.conflicts(), 10, 3);
        for (size_t i = 0; i < starts.size(); ++i) planner.add_car(int(i + 1), starts[i]);
        std::vector<double> all;
        for (int cycle = 0; cycle < 40; ++cycle) {
            planner.plan(cycle * 0.4);
            for (int id : planner.car_ids()) {
                for (const auto& p : planner.trajectory(id, cycle * 0.4, 0.1)) all.insert(all.end(), {p.t, p.x, p.y, p.vx, p.vy});
            }
        }
        return all;
    };
    const auto a = run(7), b = run(7), c = run(8);
    ASSERT_EQ(a.size(), b.size());
    EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(double)), 0);
    EXPECT_TRUE(a.size() != c.size() || std::memcmp(a.data(), c.data(), a.size() * sizeof(double)) != 0);  // routes differ
}

TEST(Planner, FourCarsReachingTheCentralIntersectionTogetherAllGetThrough)
{
    const auto graph = load_lane_graph_or_throw(kIntersection);
    Planner planner(graph, {});
    // The cross's four lanes (0.36 m apart) meet around (2.25, 2.0); each car stands 0.45 m
    // before the first lane it crosses, heading in.
    const std::vector<Pose> starts{{2.43, 1.82 - 0.45 - 0.33, M_PI / 2},   // northbound
                                   {2.07, 2.18 + 0.45 + 0.33, -M_PI / 2},  // southbound
                                   {2.07 - 0.45 - 0.33, 1.82, 0},          // eastbound
                                   {2.43 + 0.45 + 0.33, 2.18, M_PI}};      // westbound
    for (size_t i = 0; i < starts.size(); ++i) planner.add_car(int(i + 1), starts[i]);
    std::vector<double> s0;
    for (int id = 1; id <= 4; ++id) s0.push_back(planner.sample(id, 0).s);
    SimulationOptions options;
    options.duration = 20;
    const auto summary = simulate(planner, options);
    EXPECT_EQ(summary.collisions, 0u);
    EXPECT_GE(summary.min_distance_m, options.planner.margin);
    EXPECT_FALSE(summary.stalled);
    // Through the middle: each car drove past the far side of the crossing lanes.
    for (size_t i = 0; i < 4; ++i) EXPECT_GT(summary.distance_m[i], 2.0) << "car " << i + 1;
    // Where each ended (what --picture draws): its plan at the end, on the far side.
    ASSERT_EQ(summary.final_poses.size(), 4u);
    for (size_t i = 0; i < 4; ++i) {
        const auto& [id, pose] = summary.final_poses[i];
        EXPECT_EQ(id, int(i + 1));
        const Pose planned = planner.sample(id, options.duration).pose;
        EXPECT_DOUBLE_EQ(pose.x, planned.x);
        EXPECT_DOUBLE_EQ(pose.y, planned.y);
        EXPECT_GT(std::hypot(pose.x - starts[i].x, pose.y - starts[i].y), 0.5) << "car " << id << " is not where it started";
    }
}

TEST(Simulate, TheSmallestDistanceIsMeasuredHoweverFarApartTheCarsStay)
{
    // Two cars on opposite sides of the map, 0.1 s: they never come within a metre of each
    // other, and the summary still names how far apart their bodies were (once: "inf").
    const auto graph = load_lane_graph_or_throw(kIntersection);
    Planner planner(graph, {});
    planner.add_car(1, {2.43, 1.82 - 0.45 - 0.33, M_PI / 2});
    planner.add_car(2, {2.43 + 0.45 + 0.33, 2.18, M_PI});  // northbound and westbound, 1.4 m apart
    const Pose a = planner.sample(1, 0).pose, b = planner.sample(2, 0).pose;
    const double at_start = footprint_distance(planner.options().footprint, a, b);
    ASSERT_GT(std::hypot(a.x - b.x, a.y - b.y), 1.0);
    SimulationOptions options;
    options.duration = 0.1;
    const auto summary = simulate(planner, options);
    ASSERT_TRUE(std::isfinite(summary.min_distance_m));
    EXPECT_LE(summary.min_distance_m, at_start + 1e-9);
    EXPECT_GT(summary.min_distance_m, at_start - 0.05) << "0.1 s of driving";
}

TEST(Planner, ACarStoppedInItsLaneIsWaitedForNotDrivenInto)
{
    const auto graph = load_lane_graph_or_throw(kRing);
    Planner planner(graph, {});
    const Pose stopped = graph.pose_at(0, 1.6);  // on the bottom straight
    planner.add_car(2, stopped);
    planner.add_car(1, graph.pose_at(0, 0.1));   // 1.5 m behind it
    const Footprint f;
    double closest = 1e9;
    bool named = false;
    for (int cycle = 0; cycle < 50; ++cycle) {  // 20 s: car 2 never moves, whatever its plan says
        const double t = cycle * 0.4;
        planner.plan(t, {{2, stopped, 0.0}});
        for (const auto& w : planner.warnings()) named = named || w.find("vehicle 2") != std::string::npos;
        for (double dt = 0; dt < 0.4; dt += 0.02) closest = std::min(closest, footprint_distance(f, planner.sample(1, t + dt).pose, stopped));
    }
    EXPECT_GE(closest, planner.options().margin);
    EXPECT_LT(closest, 0.5);  // it came up behind and waits there
    EXPECT_LT(planner.sample(1, 20).speed, 1e-9);  // standing behind it
    EXPECT_TRUE(named) << "the planner says that car 2 does not follow its plan";
}

TEST(Planner, ACarOnNoLaneIsNamedWithItsPose)
{
    const auto graph = load_lane_graph_or_throw(kRing);
    Planner planner(graph, {});
    try {
        planner.add_car(3, {10.0, 10.0, 0.5});
        FAIL() << "a car 10 m away from every lane was placed";
    } catch (const cpm::Error& e) {
        EXPECT_NE(std::string(e.what()).find("vehicle 3 at x 10.000 y 10.000 yaw 0.500 is on no lane"), std::string::npos) << e.what();
    }
    EXPECT_FALSE(planner.has_car(3));
}

TEST(Planner, CpmLabModeGivesUpForGoodWhereTheCooperativePlannerKeepsDriving)
{
    const auto graph = load_lane_graph_or_throw(kIntersection);
    SimulationOptions options;
    options.vehicles = 6;
    options.duration = 60;
    options.start_gap = 0.5;
    options.planner.mode = Mode::cpm_lab;
    const auto baseline = simulate(graph, options);
    EXPECT_TRUE(baseline.stalled);  // it cannot stop to wait: an unavoidable conflict ends its planning
    options.planner.mode = Mode::cooperative;
    const auto ours = simulate(graph, options);
    EXPECT_FALSE(ours.stalled);
    EXPECT_EQ(ours.collisions, 0u);
    for (double d : ours.distance_m) EXPECT_GT(d, 20.0);
}
