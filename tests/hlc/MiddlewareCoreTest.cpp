// The middleware's checks and bookkeeping, without DDS.
#include <cpm/hlc/Middleware.hpp>
#include <cpm/stamp_message.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace {

using cpm::hlc::MiddlewareCore;
using cpm::hlc::MiddlewareOptions;
using cpm::hlc::Refusal;

constexpr uint64_t kMs = 1'000'000;
constexpr uint64_t kT = 1'000'000'000'000ull;  // a period's t_now

MiddlewareOptions four_cars()
{
    MiddlewareOptions o;
    o.name = "platoon";
    o.vehicle_ids = {1, 2, 3, 4};
    o.period_ns = 100 * kMs;
    o.controller_domain = 9;
    return o;
}

VehicleCommandSpeedCurvature speed(uint8_t id, uint64_t stamp, double v = 0.5, double k = 0.0)
{
    VehicleCommandSpeedCurvature c;
    c.vehicle_id(id);
    c.speed(v);
    c.curvature(k);
    cpm::stamp_message(c, stamp, 10 * kMs);
    return c;
}

TEST(MiddlewareCoreTest, TheListHoldsEachAssignedCarsValidSamplesOnly)
{
    MiddlewareCore core(four_cars());
    std::map<uint8_t, cpm::SampleResult<VehicleState>> states;
    std::map<uint8_t, cpm::SampleResult<VehicleObservation>> observations;
    states[1].valid = true;
    states[1].sample.vehicle_id(1);
    states[1].sample.speed(0.7);
    states[2].valid = false;  // no valid sample: left out
    states[9].valid = true;   // not this controller's: left out
    states[9].sample.vehicle_id(9);
    observations[4].valid = true;
    observations[4].sample.vehicle_id(4);
    const auto list = core.begin_period(kT, states, observations, 0);
    EXPECT_EQ(list.t_now(), kT);
    EXPECT_EQ(list.period_ms(), 100u);
    ASSERT_EQ(list.state_list().size(), 1u);
    EXPECT_EQ(list.state_list()[0].vehicle_id(), 1);
    EXPECT_DOUBLE_EQ(list.state_list()[0].speed(), 0.7);
    ASSERT_EQ(list.vehicle_observation_list().size(), 1u);
    EXPECT_EQ(list.vehicle_observation_list()[0].vehicle_id(), 4);
    EXPECT_EQ(list.active_vehicle_ids(), (std::vector<int32_t>{1, 2, 3, 4}));
}

TEST(MiddlewareCoreTest, ACommandStampedWithTheListsTimeGoesThrough)
{
    MiddlewareCore core(four_cars());
    (void)core.begin_period(kT, {}, {}, 0);
    EXPECT_TRUE(core.check(speed(2, kT), kT + 3 * kMs).ok);
    EXPECT_TRUE(core.check(speed(3, kT + 2 * kMs), kT + 3 * kMs).ok);  // stamped when computed
    EXPECT_EQ(core.forwarded(), 2u);
    EXPECT_EQ(core.refused(), 0u);
}

TEST(MiddlewareCoreTest, EachRefusalIsNamedAndCountedByItsReason)
{
    MiddlewareCore core(four_cars());
    const auto before_first = core.check(speed(1, kT), kT);
    EXPECT_FALSE(before_first.ok);
    EXPECT_EQ(before_first.reason, Refusal::past_period);

    (void)core.begin_period(kT, {}, {}, 0);
    const auto stranger = core.check(speed(7, kT), kT);
    EXPECT_FALSE(stranger.ok);
    EXPECT_EQ(stranger.reason, Refusal::not_assigned);
    EXPECT_EQ(stranger.why, "vehicle 7 is not assigned to this controller (it drives 1,2,3,4)");

    const auto future = core.check(speed(1, kT + 50 * kMs), kT + 10 * kMs);
    EXPECT_FALSE(future.ok);
    EXPECT_EQ(future.reason, Refusal::future_stamp);
    EXPECT_NE(future.why.find("40000 us in the future"), std::string::npos) << future.why;

    const auto past = core.check(speed(1, kT - 100 * kMs), kT + 10 * kMs);
    EXPECT_FALSE(past.ok);
    EXPECT_EQ(past.reason, Refusal::past_period);
    EXPECT_NE(past.why.find("answers a period already past"), std::string::npos) << past.why;

    const auto nan = core.check(speed(1, kT, std::numeric_limits<double>::quiet_NaN()), kT);
    EXPECT_FALSE(nan.ok);
    EXPECT_EQ(nan.reason, Refusal::bad_value);
    EXPECT_EQ(nan.why, "vehicle 1: speed = nan is not a finite number");
    const auto fast = core.check(speed(1, kT, 50.0), kT);
    EXPECT_EQ(fast.reason, Refusal::bad_value);
    EXPECT_EQ(fast.why, "vehicle 1: speed = 50 is outside [-3, 3]");
    const auto inf = core.check(speed(1, kT, 0.5, std::numeric_limits<double>::infinity()), kT);
    EXPECT_EQ(inf.reason, Refusal::bad_value);

    EXPECT_EQ(core.refused(Refusal::not_assigned), 1u);
    EXPECT_EQ(core.refused(Refusal::future_stamp), 1u);
    EXPECT_EQ(core.refused(Refusal::past_period), 2u);
    EXPECT_EQ(core.refused(Refusal::bad_value), 3u);
    EXPECT_EQ(core.forwarded(), 0u);
    const auto stats = core.stats_json();
    EXPECT_NE(stats.find("\"refused\":7"), std::string::npos) << stats;
    EXPECT_NE(stats.find("vehicle 7 is not assigned"), std::string::npos) << stats;
}

TEST(MiddlewareCoreTest, EveryCommandTypeIsCheckedByTheBridgesRules)
{
    MiddlewareCore core(four_cars());
    (void)core.begin_period(kT, {}, {}, 0);
    VehicleCommandDirect direct;
    direct.vehicle_id(1);
    direct.motor_throttle(1.5);
    cpm::stamp_message(direct, kT, 0);
    EXPECT_EQ(core.check(direct, kT).why, "vehicle 1: motor_throttle = 1.5 is outside [-1, 1]");
    VehicleCommandTrajectory trajectory;
    trajectory.vehicle_id(2);
    trajectory.trajectory_points().resize(3);
    trajectory.trajectory_points()[2].px(std::nan(""));
    cpm::stamp_message(trajectory, kT, 0);
    EXPECT_EQ(core.check(trajectory, kT).why, "vehicle 2: trajectory_points[2].px = nan is not a finite number");
    VehicleCommandPathTracking path;
    path.vehicle_id(3);
    path.speed(0.5);
    path.path().resize(1);
    path.path()[0].pose().yaw(INFINITY);
    cpm::stamp_message(path, kT, 0);
    EXPECT_EQ(core.check(path, kT).why, "vehicle 3: path[0].pose.yaw = inf is not a finite number");
    trajectory.trajectory_points()[2].px(1.0);
    EXPECT_TRUE(core.check(trajectory, kT).ok);
}

TEST(MiddlewareCoreTest, AnAnswerCountsForTheOpenPeriodOnlyWithItsResponseTime)
{
    MiddlewareCore core(four_cars());
    (void)core.begin_period(kT, {}, {}, 1000 * kMs);
    EXPECT_FALSE(core.open_period_answered());
    EXPECT_TRUE(core.answered(kT, 1007 * kMs));
    EXPECT_TRUE(core.open_period_answered());
    EXPECT_FALSE(core.answered(kT, 1008 * kMs));  // twice
    (void)core.begin_period(kT + 100 * kMs, {}, {}, 1100 * kMs);
    (void)core.begin_period(kT + 200 * kMs, {}, {}, 1200 * kMs);  // the one before closed unanswered
    EXPECT_FALSE(core.answered(kT + 100 * kMs, 1230 * kMs));        // too late
    EXPECT_TRUE(core.answered(kT + 200 * kMs, 1203 * kMs));
    EXPECT_EQ(core.periods(), 3u);
    EXPECT_EQ(core.answered_periods(), 2u);
    EXPECT_EQ(core.unanswered_periods(), 1u);
    EXPECT_EQ(core.late_answers(), 2u);
    const auto ms = core.response_ms();
    ASSERT_EQ(ms.size(), 2u);
    EXPECT_NEAR(ms[0], 7.0, 1e-9);
    EXPECT_NEAR(ms[1], 3.0, 1e-9);
}

}  // namespace
