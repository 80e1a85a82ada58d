// detail::Ring, the store's circular sequence (an object's records and its data-time index), at
// the edges of its buffer: exactly full, one past full, indices wrapped past the buffer's end,
// inserts and erases across the wrap, memory given back after a flood. It never drops an
// element by itself; the store evicts the oldest with pop_front().
#include "Ring.hpp"

#include <gtest/gtest.h>

#include <vector>

using cpm::rtdb::detail::Ring;

namespace {

std::vector<int> ring_contents(const Ring<int>& r)
{
    std::vector<int> out;
    for (size_t i = 0; i < r.size(); ++i) out.push_back(r[i]);
    return out;
}

/// from, from + 1, …, to - 1.
std::vector<int> ints_from(int from, int to)
{
    std::vector<int> out;
    for (int i = from; i < to; ++i) out.push_back(i);
    return out;
}

/// A ring holding 0 … n - 1, n its capacity: exactly full.
Ring<int> exactly_full()
{
    Ring<int> r;
    r.push_back(0);
    for (int i = 1; size_t(i) < r.capacity(); ++i) r.push_back(i);
    return r;
}

TEST(Ring, ExactlyFullHoldsEveryElementOldestFirst)
{
    const Ring<int> sut = exactly_full();
    const int n = int(sut.capacity());
    ASSERT_GT(n, 1);
    EXPECT_EQ(sut.size(), size_t(n));
    EXPECT_EQ(ring_contents(sut), ints_from(0, n));
    EXPECT_EQ(sut.front(), 0);
    EXPECT_EQ(sut.back(), n - 1);
}

TEST(Ring, OnePastFullGrowsAndLosesNothing)
{
    Ring<int> sut = exactly_full();
    const int n = int(sut.capacity());
    sut.push_back(n);
    EXPECT_GT(sut.capacity(), size_t(n));
    EXPECT_EQ(ring_contents(sut), ints_from(0, n + 1)) << "nothing is evicted but by pop_front";
}

TEST(Ring, TheOldestEvictedMakesRoomAndIndicesWrapPastTheBufferEnd)
{
    Ring<int> sut = exactly_full();
    const int n = int(sut.capacity());
    for (int i = 0; i < 5; ++i) sut.pop_front();
    for (int i = n; i < n + 5; ++i) sut.push_back(i);
    EXPECT_EQ(sut.capacity(), size_t(n)) << "the evicted elements' room is used again";
    EXPECT_EQ(ring_contents(sut), ints_from(5, n + 5));
    EXPECT_EQ(sut.front(), 5);
    EXPECT_EQ(sut.back(), n + 4);
    sut[size_t(n) - 1] = -1;  // the last index lies past the buffer's end: it is the newest element
    EXPECT_EQ(sut.back(), -1);
}

TEST(Ring, GrowingWhileWrappedKeepsTheOrder)
{
    Ring<int> sut = exactly_full();
    const int n = int(sut.capacity());
    for (int i = 0; i < 5; ++i) sut.pop_front();
    for (int i = n; i < n + 6; ++i) sut.push_back(i);  // full and wrapped, then one past full
    EXPECT_GT(sut.capacity(), size_t(n));
    EXPECT_EQ(ring_contents(sut), ints_from(5, n + 6));
}

TEST(Ring, TheOldestWrapsRoundTheBufferManyTimesWithoutGrowing)
{
    Ring<int> sut;
    for (int i = 0; i < 4; ++i) sut.push_back(i);
    const size_t capacity = sut.capacity();
    for (int i = 4; i < int(3 * capacity); ++i) {
        sut.push_back(i);
        sut.pop_front();
        ASSERT_EQ(ring_contents(sut), ints_from(i - 3, i + 1)) << "after " << i;
    }
    EXPECT_EQ(sut.capacity(), capacity);
}

TEST(Ring, InsertAndEraseAcrossTheWrapPointMoveOnlyWhatTheySay)
{
    Ring<int> sut = exactly_full();
    const int n = int(sut.capacity());
    for (int i = 0; i < n - 4; ++i) sut.pop_front();
    for (int i = n; i < n + 6; ++i) sut.push_back(i);  // n - 4 … n + 5; index 4 is the buffer's first slot
    ASSERT_EQ(ring_contents(sut), ints_from(n - 4, n + 6));
    sut.insert(4, 100);
    std::vector<int> expected = ints_from(n - 4, n + 6);
    expected.insert(expected.begin() + 4, 100);
    EXPECT_EQ(ring_contents(sut), expected);
    sut.erase(5);
    expected.erase(expected.begin() + 5);
    EXPECT_EQ(ring_contents(sut), expected);
    sut.insert(0, -1);
    sut.insert(sut.size(), 200);
    expected.insert(expected.begin(), -1);
    expected.push_back(200);
    EXPECT_EQ(ring_contents(sut), expected);
    sut.erase(0);
    sut.erase(sut.size() - 1);
    expected.erase(expected.begin());
    expected.pop_back();
    EXPECT_EQ(ring_contents(sut), expected);
}

TEST(Ring, ShrinkGivesMemoryBackAfterAFloodAndKeepsWhatIsHeld)
{
    Ring<int> sut;
    for (int i = 0; i < 1000; ++i) sut.push_back(i);
    const size_t flooded = sut.capacity();
    sut.shrink();
    EXPECT_EQ(sut.capacity(), flooded) << "full: nothing to give back";
    for (int i = 0; i < 990; ++i) sut.pop_front();
    sut.shrink();
    EXPECT_LT(sut.capacity(), flooded / 2);
    EXPECT_GE(sut.capacity(), sut.size());
    EXPECT_EQ(ring_contents(sut), ints_from(990, 1000));
    sut.push_back(1000);
    EXPECT_EQ(sut.back(), 1000);
}

}  // namespace
