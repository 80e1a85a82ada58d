// The selection rule behind Reader::get_sample, without DDS.
#include <cpm/detail/SampleSelector.hpp>

#include <cpm_test/Dds.hpp>
#include <gtest/gtest.h>

#include <memory>
#include <thread>

using cpm::detail::SampleSelector;

namespace {

using cpm_test::kMs;

void add(SampleSelector& sut, int tag, uint64_t create, uint64_t valid_after)
{
    sut.add(create, valid_after, std::make_shared<const int>(tag));
}

int tag_of(const SampleSelector::Pick& pick) { return pick.sample ? *std::static_pointer_cast<const int>(pick.sample) : -1; }

}  // namespace

TEST(SampleSelector, PicksLargestCreateStampAmongValid)
{
    SampleSelector sut(100);
    add(sut, 1, 100, 150);
    add(sut, 2, 200, 250);
    add(sut, 3, 300, 350);  // not valid yet at 300

    auto pick = sut.select(300);

    EXPECT_EQ(tag_of(pick), 2);
    EXPECT_EQ(pick.valid_after_ns, 250u);
}

TEST(SampleSelector, NewestValidEvenWhenArrivalsAreOutOfOrder)
{
    SampleSelector in_order(100), shuffled(100);
    const uint64_t creates[] = {100, 200, 300, 400};
    for (int i = 0; i < 4; ++i) add(in_order, i, creates[i], creates[i] + 10);
    for (int i : {2, 0, 3, 1}) add(shuffled, i, creates[i], creates[i] + 10);

    EXPECT_EQ(tag_of(in_order.select(350)), 2);
    EXPECT_EQ(tag_of(shuffled.select(350)), 2);
    EXPECT_EQ(tag_of(shuffled.select(1000)), 3);
}

TEST(SampleSelector, EqualCreateStampGoesToLaterArrival)
{
    SampleSelector sut(100);
    add(sut, 1, 500, 500);
    add(sut, 2, 500, 500);

    EXPECT_EQ(tag_of(sut.select(600)), 2);
    EXPECT_EQ(tag_of(sut.select(600)), 2);  // and stays the answer
}

TEST(SampleSelector, NothingValidReturnsNoSampleAndDropsNothing)
{
    SampleSelector sut(100);
    add(sut, 1, 100, 1000);
    add(sut, 2, 200, 2000);

    auto pick = sut.select(999);

    EXPECT_EQ(pick.sample, nullptr);
    EXPECT_EQ(sut.size(), 2u);
    EXPECT_EQ(tag_of(sut.select(1000)), 1);
}

TEST(SampleSelector, OlderSamplesAreDroppedAfterARead)
{
    SampleSelector sut(100);
    add(sut, 1, 100, 100);
    add(sut, 2, 200, 200);
    add(sut, 3, 300, 900);  // newer, valid later: must survive the read

    EXPECT_EQ(tag_of(sut.select(500)), 2);

    EXPECT_EQ(sut.size(), 2u);  // 2 (the pick) and 3
    EXPECT_EQ(tag_of(sut.select(1000)), 3);
    EXPECT_EQ(sut.size(), 1u);
}

TEST(SampleSelector, FutureValidAfterIsNotReturnedBeforeItsTime)
{
    SampleSelector sut(100);
    add(sut, 1, 100, 100);
    add(sut, 2, 200, 5000);

    EXPECT_EQ(tag_of(sut.select(4999)), 1);
    EXPECT_EQ(tag_of(sut.select(5000)), 2);
}

TEST(SampleSelector, BufferBoundDropsEarliestArrivalsAndCountsThem)
{
    SampleSelector sut(3);
    for (int i = 0; i < 5; ++i) add(sut, i, 100 + i, 100 + i);

    EXPECT_EQ(sut.size(), 3u);
    EXPECT_EQ(sut.overflow_count(), 2u);
    // 0 and 1 are gone: at t=102 only 2 is valid.
    EXPECT_EQ(tag_of(sut.select(102)), 2);
}

TEST(SampleSelector, CpmLabScenarioReturnsIndex4WithAge900ms)
{
    // Samples every 1 s from t0 to t0+10 s, valid 400 ms after creation.
    SampleSelector sut(2000);
    const uint64_t t0 = 1'000'000'000'000;
    for (int i = 0; i <= 10; ++i) add(sut, i, t0 + i * 1000 * kMs, t0 + i * 1000 * kMs + 400 * kMs);

    const uint64_t t_now = t0 + 5300 * kMs;
    auto pick = sut.select(t_now);

    EXPECT_EQ(tag_of(pick), 4);
    EXPECT_EQ(t_now - pick.valid_after_ns, 900 * kMs);
}

TEST(SampleSelector, ConcurrentAddAndSelectStayConsistent)
{
    SampleSelector sut(50);
    std::thread writer([&] {
        for (int i = 1; i <= 20000; ++i) add(sut, i, static_cast<uint64_t>(i), static_cast<uint64_t>(i));
    });
    int last = 0;
    bool monotone = true;
    for (int n = 0; n < 20000; ++n) {
        const int tag = tag_of(sut.select(UINT64_MAX));
        if (tag != -1) {
            monotone = monotone && tag >= last;
            last = tag;
        }
    }
    writer.join();

    EXPECT_TRUE(monotone) << "a later read returned an older sample";
    EXPECT_EQ(tag_of(sut.select(UINT64_MAX)), 20000);
}

TEST(SampleSelector, TheRingGrowsToItsCapacityOrHoldsItFromTheStartInRealTime)
{
    SampleSelector growing(100, false);
    EXPECT_EQ(growing.slots(), 8u) << "a small ring first";
    for (int i = 0; i < 30; ++i) add(growing, i, 100 + i, 100 + i);
    EXPECT_EQ(growing.slots(), 32u) << "doubled as the samples came";
    EXPECT_EQ(growing.size(), 30u);
    EXPECT_EQ(tag_of(growing.select(129)), 29);
    for (int i = 0; i < 300; ++i) add(growing, i, 1000 + i, 1000 + i);
    EXPECT_EQ(growing.slots(), 100u) << "never beyond the capacity";
    EXPECT_EQ(growing.size(), 100u);

    SampleSelector preallocated(2000, true);
    EXPECT_EQ(preallocated.slots(), 2000u) << "--realtime: every slot before the first sample";
    for (int i = 0; i < 5000; ++i) add(preallocated, i, 100 + i, 100 + i);
    EXPECT_EQ(preallocated.slots(), 2000u);
    EXPECT_EQ(preallocated.overflow_count(), 3000u);
}

TEST(SampleSelector, AReadAcrossTheRingsWrapKeepsWhatMayStillWinInArrivalOrder)
{
    // Capacity 4, six arrivals: the ring has wrapped (head in the middle). Created out of order.
    SampleSelector sut(4, true);
    const int creates[] = {10, 11, 50, 20, 40, 30};
    for (int i = 0; i < 6; ++i) add(sut, i, creates[i], creates[i]);
    // Held: tags 2 (50), 3 (20), 4 (40), 5 (30). At t = 45 valid are 20, 40, 30: 40 wins; 50 may
    // still win later and stays, as does the pick; 20 and 30 can never win again.
    EXPECT_EQ(tag_of(sut.select(45)), 4);
    EXPECT_EQ(sut.size(), 2u);
    EXPECT_EQ(tag_of(sut.select(45)), 4) << "the pick is kept";
    EXPECT_EQ(tag_of(sut.select(60)), 2);
    EXPECT_EQ(sut.size(), 1u);
    // And the compacted ring takes new arrivals behind what it kept.
    for (int i = 6; i < 9; ++i) add(sut, i, 60 + i, 60 + i);
    EXPECT_EQ(sut.size(), 4u);
    EXPECT_EQ(tag_of(sut.select(100)), 8);
}
