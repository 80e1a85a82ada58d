// cpm::update_rate_hz: the rate `cpm dump` shows, over the samples an object holds.
#include <cpm/HistoryClient.hpp>

#include <gtest/gtest.h>

namespace {

constexpr uint64_t kS = 1'000'000'000;

HistoryObject object(uint64_t created, uint64_t deleted, uint64_t held, uint64_t window = 10 * kS)
{
    HistoryObject o;
    o.created_ts(created);
    o.deleted_ts(deleted);
    o.samples_held(held);
    o.history_interval_ns(window);
    return o;
}

TEST(HistoryRate, APeriodicObjectShowsItsRateOverTheWindowItHolds)
{
    // 100 Hz for a minute, 10 s held.
    EXPECT_DOUBLE_EQ(cpm::update_rate_hz(object(1000 * kS, 0, 1000), 1060 * kS), 100.0);
    // Only 3 s old: 300 samples over those 3 s.
    EXPECT_DOUBLE_EQ(cpm::update_rate_hz(object(1000 * kS, 0, 300), 1003 * kS), 100.0);
}

TEST(HistoryRate, ARecordingThatKeepsEverySampleShowsThemOverTheTimeTheySpan)
{
    // 50 Hz for 75 s, every sample kept though the live window was 60 s: 50 Hz, not 3750 / 60.
    HistoryObject recorded = object(1000 * kS, 0, 3750, 60 * kS);
    recorded.oldest_commit_ns(1000 * kS);
    EXPECT_DOUBLE_EQ(cpm::update_rate_hz(recorded, 1075 * kS), 50.0);
    // A live window holds less than its life: the window it holds, as before.
    HistoryObject live = object(1000 * kS, 0, 500, 10 * kS);
    live.oldest_commit_ns(1065 * kS + 20'000'000);
    EXPECT_DOUBLE_EQ(cpm::update_rate_hz(live, 1075 * kS), 50.0);
}

TEST(HistoryRate, TwoSamplesAMomentApartAreNotAFastObject)
{
    // Two log lines 0.1 ms apart, 3 s ago: 1 / avg cycle would say 10 kHz.
    EXPECT_NEAR(cpm::update_rate_hz(object(1000 * kS, 0, 2), 1003 * kS), 2.0 / 3.0, 1e-9);
}

TEST(HistoryRate, ADeletedObjectShowsTheRateItHadUntilItsDeletion)
{
    // 50 Hz until deleted at 1050 s; asked 5 s later, its last 10 s are still held.
    EXPECT_DOUBLE_EQ(cpm::update_rate_hz(object(1000 * kS, 1050 * kS, 500), 1055 * kS), 50.0);
}

TEST(HistoryRate, ProcessesEmptyObjectsShortLivesAndClocksAheadShowNoRate)
{
    HistoryObject process = object(1000 * kS, 0, 5);
    process.is_process(true);
    EXPECT_EQ(cpm::update_rate_hz(process, 1003 * kS), 0.0);
    EXPECT_EQ(cpm::update_rate_hz(object(1000 * kS, 0, 0), 1003 * kS), 0.0);
    EXPECT_EQ(cpm::update_rate_hz(object(1000 * kS, 0, 5), 999 * kS), 0.0);  // created "after" now
    // Two stop requests 3 ms apart, then deleted: too short a life to tell a rate.
    EXPECT_EQ(cpm::update_rate_hz(object(1000 * kS, 1000 * kS + 3'000'000, 2), 1005 * kS), 0.0);
}

}  // namespace
