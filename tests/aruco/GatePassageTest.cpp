// The gate judge (gate_passages) that the closed-loop tests and the run report rely on, refereed
// by hand: each expected crossing, offset and clearance below is worked out on paper from the
// gate's two markers and the path's straight pieces, not by the code under test.
#include <cpm/aruco/GateCourse.hpp>

#include <gtest/gtest.h>

#include <cmath>

using namespace cpm;

namespace {

/// One gate at x = 2 across the x axis: left marker (id 0) at (2, 0.4), right (id 1) at
/// (2, -0.4), each 0.2 m wide. Half the gate is 0.4 m; a marker's inner edge is 0.3 m from the
/// centre. The car is 0.2 m wide, so a centred car clears each marker by 0.2 m.
vehicle::World straight_gate()
{
    return vehicle::World({}, {{.id = 0, .x = 2, .y = 0.4, .size = 0.2, .z = 0.15}, {.id = 1, .x = 2, .y = -0.4, .size = 0.2, .z = 0.15}},
                          {{.left = 0, .right = 1}});
}

/// A straight drive from (x0, y0) at t0 to (x1, y1) at t1, in `steps` pieces.
std::vector<aruco::PathPoint> line(double x0, double y0, double t0, double x1, double y1, double t1, int steps = 8)
{
    std::vector<aruco::PathPoint> path;
    for (int i = 0; i <= steps; ++i) {
        const double f = double(i) / steps;
        path.push_back({.t = t0 + f * (t1 - t0), .pose = {x0 + f * (x1 - x0), y0 + f * (y1 - y0), std::atan2(y1 - y0, x1 - x0)}});
    }
    return path;
}

constexpr double kCar = 0.2;

}  // namespace

TEST(GatePassage, AnOffCentrePassIsTimedAndMeasuredFromTheCentre)
{
    // Along y = 0.1 from x = 0 (t = 0) to x = 4 (t = 4): through the gate at x = 2, t = 2, 0.1 m left.
    const auto sut = aruco::gate_passages(straight_gate(), line(0, 0.1, 0, 4, 0.1, 4), kCar);
    ASSERT_EQ(sut.size(), 1u);
    EXPECT_TRUE(sut[0].passed);
    EXPECT_NEAR(sut[0].t, 2.0, 1e-9);
    EXPECT_NEAR(sut[0].offset, 0.1, 1e-9);
    EXPECT_NEAR(sut[0].clearance, 0.3 - 0.1 - 0.1, 1e-9);  // inner edge, offset, half the car
    EXPECT_TRUE(aruco::all_gates_passed(sut, 0.05));
}

TEST(GatePassage, APassAtAnAngleIsMeasuredWhereItCrossesTheGateLine)
{
    // From (1, -0.5) at t = 0 to (3, 0.5) at t = 1: y = 0 at x = 2, halfway, t = 0.5.
    const auto sut = aruco::gate_passages(straight_gate(), line(1, -0.5, 0, 3, 0.5, 1, 3), kCar);
    ASSERT_TRUE(sut[0].passed);
    EXPECT_NEAR(sut[0].t, 0.5, 1e-9);
    EXPECT_NEAR(sut[0].offset, 0.0, 1e-9);
    EXPECT_NEAR(sut[0].clearance, 0.2, 1e-9);
}

TEST(GatePassage, AGateTurnedBy45DegreesMeasuresAlongItsOwnLine)
{
    // The same gate turned 45° about its centre (2, 0): left marker at (2 - 0.4·sin45, 0.4·cos45).
    const double d = 0.4 / std::sqrt(2.0);
    const vehicle::World turned({}, {{.id = 0, .x = 2 - d, .y = d, .size = 0.2, .z = 0.15}, {.id = 1, .x = 2 + d, .y = -d, .size = 0.2, .z = 0.15}},
                                {{.left = 0, .right = 1}});
    // Driving along y = 0.1 meets the gate's line where s·cos45 = 0.1: s = 0.1·√2 from the centre.
    const auto sut = aruco::gate_passages(turned, line(0, 0.1, 0, 4, 0.1, 4), kCar);
    ASSERT_TRUE(sut[0].passed);
    EXPECT_NEAR(sut[0].offset, 0.1 * std::sqrt(2.0), 1e-9);
    EXPECT_NEAR(sut[0].t, 2.0 - 0.1, 1e-9);  // at x = 2 - 0.1
}

TEST(GatePassage, AMissBy1cmOrAPassTheWrongWayIsNoPassage)
{
    // The line of the gate crossed 1 cm outside the left marker's centre.
    EXPECT_FALSE(aruco::gate_passages(straight_gate(), line(0, 0.41, 0, 4, 0.41, 4), kCar)[0].passed);
    // Just inside it: a passage, with a clearance below zero (the car's side hits the marker).
    const auto scraped = aruco::gate_passages(straight_gate(), line(0, 0.39, 0, 4, 0.39, 4), kCar);
    ASSERT_TRUE(scraped[0].passed);
    EXPECT_NEAR(scraped[0].clearance, 0.3 - 0.39 - 0.1, 1e-9);
    std::string why;
    EXPECT_FALSE(aruco::all_gates_passed(scraped, 0.05, &why));
    EXPECT_EQ(why, "gate 1 passed 0.390 m from its centre: -0.190 m from a marker (need 0.050)");
    // Through the middle but driving -x: the car came from the far side.
    EXPECT_FALSE(aruco::gate_passages(straight_gate(), line(4, 0, 0, 0, 0, 4), kCar)[0].passed);
}

TEST(GatePassage, TheClosedLoopTestsBoundIsAnOffsetOf15cm)
{
    // What "5 cm clearance" allows on the closed-loop courses (gate 0.8 m, markers 0.2 m, the
    // simulator's car 0.20 m wide): |offset| <= 0.3 - 0.1 - 0.05 = 0.15 m either side.
    const double car = vehicle::VehicleParameters{}.width;
    ASSERT_DOUBLE_EQ(car, 0.20);
    const auto inside = aruco::gate_passages(straight_gate(), line(0, -0.149, 0, 4, -0.149, 4), car);
    const auto outside = aruco::gate_passages(straight_gate(), line(0, 0.152, 0, 4, 0.152, 4), car);
    EXPECT_TRUE(aruco::all_gates_passed(inside, 0.05));
    EXPECT_FALSE(aruco::all_gates_passed(outside, 0.05));
}
