// The planner on the lab map for N = 1..20 cars and five seeds, 60 simulated seconds each,
// against ideal cars: what it sends stays within the limits and no two bodies come closer than
// the margin at any 20 ms sample; every plan ends standing; every car drives on.
#include "BodyGap.hpp"

#include <cpm/routing/Simulate.hpp>

#include <gtest/gtest.h>

#include <array>
#include <future>
#include <limits>
#include <vector>
#include <cpm_test/SourceDir.hpp>

using namespace cpm::routing;

class RoutingSweep : public ::testing::TestWithParam<size_t>
{
};

TEST_P(RoutingSweep, SixtySecondsWithinTheMarginAndTheLimitsForFiveSeeds)
{
    const auto graph = load_lane_graph_or_throw(cpm_test::source_dir() + "/scenarios/lanes/intersection.json");
    // The tests' own referee of the gap between bodies (not the planner's footprint_distance):
    // the least gap of every pair at every sample, per seed.
    std::array<double, 5> referee_gap;
    referee_gap.fill(std::numeric_limits<double>::infinity());
    auto options_for = [&](uint64_t seed) {
        SimulationOptions options;
        options.vehicles = GetParam();
        options.duration = 60;
        options.planner.seed = seed;
        options.observe = [&gap = referee_gap[seed - 1], f = options.planner.footprint](double, const std::vector<Pose>& poses) {
            for (size_t i = 0; i < poses.size(); ++i) {
                for (size_t j = i + 1; j < poses.size(); ++j) {
                    gap = routing_test::least_gap(f, poses[i], poses[j], gap);
                }
            }
        };
        return options;
    };
    // The five seeds are independent simulations: run side by side, judged in order.
    std::vector<std::future<SimulationSummary>> runs;
    for (uint64_t seed = 1; seed <= 5; ++seed) {
        runs.push_back(std::async(std::launch::async, [&graph, options = options_for(seed)] { return simulate(graph, options); }));
    }
    for (uint64_t seed = 1; seed <= 5; ++seed) {
        const auto options = options_for(seed);
        const auto s = runs[seed - 1].get();
        SCOPED_TRACE("seed " + std::to_string(seed) + ": " + s.to_json());
        EXPECT_EQ(s.collisions, 0u);
        if (options.vehicles > 1) {
            EXPECT_GE(s.min_distance_m, options.planner.margin);
            // The referee agrees: no two bodies closer than the margin (to within its half millimetre).
            EXPECT_GE(referee_gap[seed - 1], options.planner.margin - 0.0005);
            EXPECT_NEAR(referee_gap[seed - 1], s.min_distance_m, 0.0005);
        }
        EXPECT_LE(s.max_speed, options.planner.v_max + 1e-9);
        EXPECT_LE(s.max_acceleration, options.planner.a_max + 1e-6);
        EXPECT_LE(s.max_point_spacing, options.planner.v_max * 0.1 + 1e-6);  // points 0.1 s apart
        EXPECT_GE(s.min_reach_s, 1.0);  // every trajectory sent covers at least a second ahead
        EXPECT_LT(s.max_end_speed, 1e-9);  // every plan ends standing, so the next one is always feasible
        // And every car drives: none is locked in a ring of waiting cars (each standing behind
        // the next, around a loop of the map). In 60 s at 1 m/s a free car covers 60 m; 10 m
        // is a car that stood most of the minute.
        for (size_t i = 0; i < s.distance_m.size(); ++i) EXPECT_GT(s.distance_m[i], 10.0) << "car " << i + 1;
    }
}

INSTANTIATE_TEST_SUITE_P(Cars, RoutingSweep, ::testing::Range<size_t>(1, 21),
                         [](const ::testing::TestParamInfo<size_t>& info) { return std::to_string(info.param) + "Cars"; });
