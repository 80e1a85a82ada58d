// detail::ObjectState, what the store holds of one object, at its eviction edges: by age (the
// retention window, a sample exactly a window old stays), the oldest one at a time (as the
// byte budget evicts), everything, and with sequence numbers past 2^32 (the data-time index
// keeps their low 32 bits). Each answer is one a store's user sees: which samples are held, in
// which order by commit and by data time, and what a query for an evicted time says.
#include "ObjectState.hpp"

#include <gtest/gtest.h>

#include <string>

using cpm::rtdb::By;
using cpm::rtdb::Found;
using cpm::rtdb::Status;
using cpm::rtdb::Which;
using cpm::rtdb::detail::ObjectState;

namespace {

/// Commits a sample whose payload names its commit time ("c300").
void commit_sample(ObjectState& sut, uint64_t commit, uint64_t data)
{
    const std::string payload = "c" + std::to_string(commit);
    sut.append(commit, {data, data, 0, reinterpret_cast<const uint8_t*>(payload.data()), payload.size(), 0});
}

std::string payload_text(const cpm::rtdb::StoredSample& s) { return std::string(s.payload.begin(), s.payload.end()); }

/// The held samples by commit time, as a range query lists them: "c200 c300".
std::string held_by_commit(const ObjectState& s)
{
    std::string out;
    for (size_t i = 0; i < s.records.size(); ++i) out += (out.empty() ? "" : " ") + payload_text(s.copy(s.records[i]));
    return out;
}

/// The held samples by data time, as a range query by data time lists them.
std::string held_by_data(const ObjectState& s)
{
    std::string out;
    for (size_t i = 0; i < s.records.size(); ++i) out += (out.empty() ? "" : " ") + payload_text(s.copy(s.nth_by_data(i)));
    return out;
}

/// "c300" for a sample found, else the status's name.
std::string answer_of(const Found& f) { return f.ok() ? payload_text(f.sample) : std::string(to_string(f.status)); }

TEST(ObjectState, EvictingByAgeDropsOnlySamplesOlderThanTheWindow)
{
    ObjectState sut;
    sut.retention.window_ns = 100;
    for (uint64_t c = 100; c <= 400; c += 100) commit_sample(sut, c, c / 10);

    const auto evicted = sut.evict_window(300);

    EXPECT_EQ(evicted.samples, 1u);
    EXPECT_EQ(evicted.bytes, 4u);
    EXPECT_EQ(held_by_commit(sut), "c200 c300 c400") << "c200 is exactly a window older than 300: it stays";
    EXPECT_EQ(answer_of(sut.found(Which::at, 150, By::commit)), "evicted");
    EXPECT_EQ(answer_of(sut.found(Which::at, 99, By::commit)), "not_found") << "before anything was stored";
    EXPECT_EQ(answer_of(sut.found(Which::at, 200, By::commit)), "c200");
    EXPECT_EQ(answer_of(sut.found(Which::younger, 50, By::commit)), "evicted") << "the one after 50 was c100, gone";
    EXPECT_EQ(answer_of(sut.found(Which::younger, 100, By::commit)), "c200");
    EXPECT_EQ(answer_of(sut.found(Which::latest, 0, By::commit)), "c400");
    const auto info = sut.described();
    EXPECT_EQ(info.samples_held, 3u);
    EXPECT_EQ(info.bytes_held, 12u);
    EXPECT_EQ(info.oldest_commit_ns, 200u);
    EXPECT_EQ(info.samples_total, 4u);

    EXPECT_EQ(sut.evict_window(300).samples, 0u) << "nothing more is older than the window";
    EXPECT_EQ(sut.evict_window(301).samples, 1u) << "c200 is now a window and 1 ns old";
    EXPECT_EQ(held_by_commit(sut), "c300 c400");
}

TEST(ObjectState, EvictingEverythingByAgeAnswersEvictedNotNotFound)
{
    ObjectState sut;
    sut.retention.window_ns = 100;
    for (uint64_t c = 100; c <= 300; c += 100) commit_sample(sut, c, c);

    const auto evicted = sut.evict_window(10'000);

    EXPECT_EQ(evicted.samples, 3u);
    EXPECT_EQ(evicted.bytes, 12u);
    EXPECT_EQ(held_by_commit(sut), "");
    EXPECT_EQ(sut.described().bytes_held, 0u);
    EXPECT_EQ(answer_of(sut.found(Which::latest, 0, By::commit)), "evicted");
    EXPECT_EQ(answer_of(sut.found(Which::at, 250, By::data)), "evicted");
    commit_sample(sut, 10'100, 10'100);
    EXPECT_EQ(answer_of(sut.found(Which::latest, 0, By::commit)), "c10100") << "a sample after the eviction is held again";
}

// Data times 50, 10, 40, 20, 60, 30 for commits 100 … 600: by data time the order is
// c200 c400 c600 c300 c100 c500.
void commit_out_of_order(ObjectState& sut)
{
    const uint64_t data[] = {50, 10, 40, 20, 60, 30};
    for (uint64_t i = 0; i < 6; ++i) commit_sample(sut, 100 * (i + 1), data[i]);
}

void expect_the_two_oldest_evicted(ObjectState& sut)
{
    ASSERT_EQ(held_by_data(sut), "c200 c400 c600 c300 c100 c500");
    EXPECT_EQ(sut.evict_front(), 4u);  // c100, the oldest by commit, though not by data time
    EXPECT_EQ(sut.evict_front(), 4u);  // c200, the oldest by data time
    EXPECT_EQ(held_by_commit(sut), "c300 c400 c500 c600");
    EXPECT_EQ(held_by_data(sut), "c400 c600 c300 c500");
    EXPECT_EQ(answer_of(sut.found(Which::at, 45, By::data)), "c300");
    EXPECT_EQ(answer_of(sut.found(Which::at, 20, By::data)), "c400");
    EXPECT_EQ(answer_of(sut.found(Which::older, 20, By::data)), "evicted") << "c200 (data 10) is gone";
    EXPECT_EQ(answer_of(sut.found(Which::younger, 55, By::data)), "c500");
    EXPECT_EQ(answer_of(sut.found(Which::at, 250, By::commit)), "evicted");
    EXPECT_EQ(answer_of(sut.found(Which::at, 350, By::commit)), "c300");
    EXPECT_EQ(sut.described().samples_held, 4u);
}

TEST(ObjectState, EvictingTheOldestOneAtATimeKeepsCommitAndDataTimeOrder)
{
    ObjectState sut;
    commit_out_of_order(sut);
    expect_the_two_oldest_evicted(sut);
}

TEST(ObjectState, SequenceNumbersPast32BitsKeepTheDataTimeIndexRight)
{
    // As after 2^32 samples (50 days at 1 kHz): the index entries' 32 bits wrap round while
    // the samples are held.
    ObjectState sut;
    sut.head_seq = (uint64_t(1) << 32) - 3;
    commit_out_of_order(sut);
    expect_the_two_oldest_evicted(sut);
}

}  // namespace
