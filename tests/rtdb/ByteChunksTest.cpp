// detail::ByteChunks, the payload bytes of one object in the store, at its chunk edges: a chunk
// filled exactly, a sample that would cross into the next chunk, one larger than a chunk, a
// chunk freed when its last sample is evicted, the only chunk begun again. Whatever happens
// around it, a held sample's bytes stay where push() put them, unchanged.
#include "ByteChunks.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <deque>
#include <vector>

using cpm::rtdb::detail::ByteChunks;

namespace {

constexpr size_t kChunk = ByteChunks::kChunk;

/// n bytes that differ from sample to sample.
std::vector<uint8_t> payload_of(size_t n, uint64_t seq)
{
    std::vector<uint8_t> out(n);
    for (size_t i = 0; i < n; ++i) out[i] = uint8_t(seq * 31 + i * 7);
    return out;
}

struct HeldSample
{
    const uint8_t* at;
    std::vector<uint8_t> bytes;
    bool intact() const { return bytes.empty() || std::memcmp(at, bytes.data(), bytes.size()) == 0; }
};

/// The chunks and what was pushed into them, in order.
struct Chunks
{
    ByteChunks sut;
    std::deque<HeldSample> held;
    uint64_t next_seq = 0;

    const uint8_t* push(size_t size)
    {
        auto bytes = payload_of(size, next_seq);
        const uint8_t* at = sut.push(bytes.data(), bytes.size(), next_seq++);
        held.push_back({at, std::move(bytes)});
        return at;
    }
    void pop()
    {
        sut.pop();
        held.pop_front();
    }
    bool all_intact() const
    {
        for (const auto& s : held) {
            if (!s.intact()) return false;
        }
        return true;
    }
};

TEST(ByteChunks, SamplesFillAChunkExactlyBeforeTheNextIsTaken)
{
    Chunks c;
    const uint8_t* first = c.push(kChunk / 4);
    for (size_t i = 1; i < 4; ++i) EXPECT_EQ(c.push(kChunk / 4), first + i * (kChunk / 4)) << "side by side in one chunk";
    EXPECT_EQ(c.sut.chunks(), 1u) << "four quarters fill one chunk exactly";
    c.push(1);
    EXPECT_EQ(c.sut.chunks(), 2u);
    EXPECT_TRUE(c.all_intact());
}

TEST(ByteChunks, ASampleThatWouldCrossAChunkBoundaryGoesWholeIntoTheNext)
{
    Chunks c;
    c.push(kChunk - 100);
    c.push(101);  // one byte more than the first chunk has left
    EXPECT_EQ(c.sut.chunks(), 2u);
    c.push(kChunk - 101);  // exactly what the second has left
    EXPECT_EQ(c.sut.chunks(), 2u);
    EXPECT_TRUE(c.all_intact()) << "no sample is split between chunks";
}

TEST(ByteChunks, ASampleLargerThanAChunkGetsAChunkOfItsOwn)
{
    Chunks c;
    c.push(100);
    c.push(3 * kChunk + 5);
    EXPECT_EQ(c.sut.chunks(), 2u);
    c.push(1);
    EXPECT_EQ(c.sut.chunks(), 3u) << "the large sample's chunk has no room left";
    EXPECT_TRUE(c.all_intact());
}

TEST(ByteChunks, EvictingTheLastSampleOfAChunkFreesItAndMovesNothing)
{
    Chunks c;
    for (int i = 0; i < 5; ++i) c.push(kChunk / 4);  // a full chunk and one sample in a second
    ASSERT_EQ(c.sut.chunks(), 2u);
    for (int i = 0; i < 3; ++i) c.pop();
    EXPECT_EQ(c.sut.chunks(), 2u) << "the first chunk still holds a sample";
    c.pop();
    EXPECT_EQ(c.sut.chunks(), 1u);
    EXPECT_TRUE(c.all_intact()) << "the sample held in the second chunk stayed where it was";
}

TEST(ByteChunks, TheOnlyChunkEmptiedByEvictionIsBegunAgainFromItsStart)
{
    Chunks c;
    const uint8_t* first = c.push(100);
    c.push(200);
    c.pop();
    c.pop();
    EXPECT_EQ(c.sut.chunks(), 1u) << "kept for the next sample";
    EXPECT_EQ(c.push(300), first);
    EXPECT_TRUE(c.all_intact());
}

TEST(ByteChunks, AnEmptiedOnlyChunkTooSmallForTheNextSampleIsFreed)
{
    Chunks c;
    c.push(100);
    c.pop();
    c.push(2 * kChunk);
    EXPECT_EQ(c.sut.chunks(), 1u) << "the empty chunk went, the large sample has one of its own";
    c.push(100);
    c.pop();  // the large sample: its chunk goes, the newer one stays
    EXPECT_EQ(c.sut.chunks(), 1u);
    EXPECT_TRUE(c.all_intact());
}

TEST(ByteChunks, SamplesOfMixedSizesStayIntactUntilTheyAreEvictedOldestFirst)
{
    Chunks c;
    for (int round = 0; round < 1000; ++round) {
        c.push(1 + size_t(round * 977 % 9000));  // up to 9 KB: a chunk holds one to hundreds
        if (round % 3 == 2) c.pop();
        if (round % 100 == 99) {
            ASSERT_TRUE(c.all_intact()) << "round " << round;
        }
    }
    while (!c.held.empty()) {
        ASSERT_TRUE(c.held.front().intact()) << c.held.size() << " held";
        c.pop();
    }
    EXPECT_EQ(c.sut.chunks(), 1u) << "everything evicted: the last chunk is kept, the others freed";
}

}  // namespace
