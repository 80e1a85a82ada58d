// The query matrix of the store: every query x {empty object, before first, equal to a stored
// time, between two, after last, evicted, deleted-but-held, purged}, by commit and by data
// time, with data times arriving out of order.
#include <cpm/rtdb/Store.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <random>
#include <string>

using namespace cpm::rtdb;

namespace {

// Three samples: commit 100, 200, 300 with data times 10, 30, 20 (the third arrives late).
// By data time the order is 10 (c100), 20 (c300), 30 (c200).
constexpr uint64_t kWindow = 250;

struct Fixture
{
    Store store{StoreOptions{{kWindow, 1 << 20}, 1 << 30}};
    Oid oid = store.add_object({.topic = "vehicleState", .key = "3", .type_name = "VehicleState", .created_ts = 1});

    void put(uint64_t commit, uint64_t data)
    {
        const std::string payload = "sample c" + std::to_string(commit);
        EXPECT_EQ(store.commit(oid, {data, data + 5, commit - 1, reinterpret_cast<const uint8_t*>(payload.data()), payload.size()}, commit), commit);
    }
    void fill()
    {
        put(100, 10);
        put(200, 30);
        put(300, 20);
    }
};

enum class Q { latest, at, older, younger, range };

/// "c200" for a found sample (its commit time), otherwise the status's name.
std::string answer(const Found& f)
{
    if (!f.ok()) return std::string(to_string(f.status));
    EXPECT_EQ(std::string(f.sample.payload.begin(), f.sample.payload.end()), "sample c" + std::to_string(f.sample.commit_ns));
    EXPECT_EQ(f.sample.valid_after_ns, f.sample.data_ns + 5);
    EXPECT_EQ(f.sample.source_ns, f.sample.commit_ns - 1);
    return "c" + std::to_string(f.sample.commit_ns);
}

std::string answer(const Range& r)
{
    if (r.status != Status::ok && r.status != Status::partial) return std::string(to_string(r.status));
    std::string s = r.status == Status::partial ? "partial:" : "";
    for (auto& x : r.samples) s += (s.empty() || s.back() == ':' ? "c" : " c") + std::to_string(x.commit_ns);
    return s;
}

std::string ask_copy(const Store& s, Oid oid, Q q, uint64_t t, By by)
{
    switch (q) {
    case Q::latest: return answer(s.latest(oid));
    case Q::at: return answer(s.at(oid, t, by));
    case Q::older: return answer(s.older(oid, t, by));
    case Q::younger: return answer(s.younger(oid, t, by));
    case Q::range: return answer(s.range(oid, t, t + 100, by));
    }
    return "";
}

/// The same query seen in place (Store::view).
std::string viewed(const Store& s, Oid oid, Which which, uint64_t t, By by)
{
    Found f;
    int calls = 0;
    f.status = s.view(oid, which, t, by, [&](const SampleView& v) {
        ++calls;
        f.sample = {v.commit_ns, v.data_ns, v.valid_after_ns, v.source_ns, std::vector<uint8_t>(v.data, v.data + v.size)};
    });
    EXPECT_EQ(calls, f.ok() ? 1 : 0);
    return answer(f);
}

/// The answer of the copying call, checked to be the same as the one seen in place.
std::string ask(const Store& s, Oid oid, Q q, uint64_t t, By by)
{
    const std::string copied = ask_copy(s, oid, q, t, by);
    if (q != Q::range) {
        const Which which = q == Q::latest ? Which::latest : q == Q::at ? Which::at : q == Q::older ? Which::older : Which::younger;
        EXPECT_EQ(viewed(s, oid, which, t, by), copied) << "Store::view answers differently";
    }
    return copied;
}

struct Case
{
    const char* situation;
    By by;
    uint64_t t;
    const char *at, *older, *younger, *range;  // range is [t, t + 100)
};

class StoreQueryMatrix : public ::testing::TestWithParam<Case>
{
};

// Scenarios "evicted" (c100 gone), "deleted" (deleted, still held) and "purged" are set up
// by the situation name; the others query the three samples.
TEST_P(StoreQueryMatrix, AnswersAsSpecified)
{
    const Case& c = GetParam();
    Fixture f;
    const std::string situation = c.situation;
    if (situation != "empty") f.fill();
    if (situation == "evicted") f.store.expire(100 + kWindow + 1);
    if (situation == "deleted") {
        f.store.mark_deleted(f.oid, 310);
        f.store.expire(320);
    }
    if (situation == "purged") {
        f.store.mark_deleted(f.oid, 310);
        f.store.expire(310 + kWindow + 1);
    }
    EXPECT_EQ(ask(f.store, f.oid, Q::at, c.t, c.by), c.at) << situation << " at " << c.t;
    EXPECT_EQ(ask(f.store, f.oid, Q::older, c.t, c.by), c.older) << situation << " older " << c.t;
    EXPECT_EQ(ask(f.store, f.oid, Q::younger, c.t, c.by), c.younger) << situation << " younger " << c.t;
    EXPECT_EQ(ask(f.store, f.oid, Q::range, c.t, c.by), c.range) << situation << " range from " << c.t;
}

INSTANTIATE_TEST_SUITE_P(
    ByCommitTime, StoreQueryMatrix,
    ::testing::Values(Case{"empty", By::commit, 150, "not_found", "not_found", "not_found", "not_found"},
                      Case{"before first", By::commit, 50, "not_found", "not_found", "c100", "c100"},
                      Case{"equal", By::commit, 200, "c200", "c100", "c300", "c200"},
                      Case{"between", By::commit, 250, "c200", "c200", "c300", "c300"},
                      Case{"after last", By::commit, 400, "c300", "c300", "not_yet", "not_yet"},
                      Case{"evicted", By::commit, 150, "evicted", "evicted", "c200", "c200"},
                      Case{"evicted", By::commit, 20, "not_found", "not_found", "evicted", "evicted"},
                      Case{"deleted", By::commit, 250, "c200", "c200", "c300", "c300"},
                      Case{"purged", By::commit, 250, "unknown_object", "unknown_object", "unknown_object", "unknown_object"}));

INSTANTIATE_TEST_SUITE_P(
    ByDataTime, StoreQueryMatrix,
    ::testing::Values(Case{"empty", By::data, 15, "not_found", "not_found", "not_found", "not_found"},
                      Case{"before first", By::data, 5, "not_found", "not_found", "c100", "c100 c300 c200"},
                      Case{"equal", By::data, 20, "c300", "c100", "c200", "c300 c200"},
                      Case{"between", By::data, 25, "c300", "c300", "c200", "c200"},
                      Case{"after last", By::data, 40, "c200", "c200", "not_yet", "not_yet"},
                      Case{"evicted", By::data, 15, "evicted", "evicted", "c300", "c300 c200"},
                      Case{"evicted", By::data, 5, "not_found", "not_found", "evicted", "partial:c300 c200"},
                      Case{"deleted", By::data, 25, "c300", "c300", "c200", "c200"},
                      Case{"purged", By::data, 25, "unknown_object", "unknown_object", "unknown_object", "unknown_object"}));

TEST(StoreQuery, LatestInEverySituation)
{
    Fixture f;
    EXPECT_EQ(ask(f.store, f.oid, Q::latest, 0, By::commit), "not_found");
    f.fill();
    EXPECT_EQ(ask(f.store, f.oid, Q::latest, 0, By::commit), "c300");  // the last committed, whatever its data time
    f.store.mark_deleted(f.oid, 310);
    EXPECT_EQ(ask(f.store, f.oid, Q::latest, 0, By::commit), "c300");
    f.store.expire(300 + kWindow + 1);
    EXPECT_EQ(ask(f.store, f.oid, Q::latest, 0, By::commit), "evicted");
    f.store.expire(310 + kWindow + 1);
    EXPECT_EQ(ask(f.store, f.oid, Q::latest, 0, By::commit), "unknown_object");
}

TEST(StoreQuery, CommitTimesStrictlyIncreaseWhenTheClockTies)
{
    Fixture f;
    uint8_t b = 0;
    EXPECT_EQ(f.store.commit(f.oid, {1, 1, 0, &b, 1}, 500), 500u);
    EXPECT_EQ(f.store.commit(f.oid, {2, 2, 0, &b, 1}, 500), 501u);
    EXPECT_EQ(f.store.commit(f.oid, {3, 3, 0, &b, 1}, 400), 502u);  // a clock step back does not reorder
    EXPECT_EQ(f.store.at(f.oid, 501).sample.data_ns, 2u);
}

TEST(StoreQuery, EqualDataTimesAnswerWithTheOneCommittedLast)
{
    Fixture f;
    f.put(100, 50);
    f.put(200, 50);
    f.put(300, 40);
    EXPECT_EQ(answer(f.store.at(f.oid, 50, By::data)), "c200");
    EXPECT_EQ(answer(f.store.younger(f.oid, 40, By::data)), "c100");
    EXPECT_EQ(answer(f.store.range(f.oid, 0, 100, By::data)), "c300 c100 c200");
}

TEST(StoreQuery, RangeHonoursItsLimitAndSaysSo)
{
    Fixture f;
    f.fill();
    auto r = f.store.range(f.oid, 0, 1000, By::commit, 2);
    EXPECT_EQ(answer(r), "c100 c200");
    EXPECT_TRUE(r.truncated);
    EXPECT_EQ(answer(f.store.range(f.oid, 300, 200)), "not_found");  // t1 < t0 is empty
}

TEST(StoreQuery, ARangeReachingIntoTheEvictedPartIsPartialWithWhatIsHeld)
{
    Fixture f;
    f.fill();
    f.store.expire(100 + kWindow + 1);  // c100 (data 10) goes
    EXPECT_EQ(answer(f.store.range(f.oid, 0, 1000)), "partial:c200 c300");
    EXPECT_EQ(answer(f.store.range(f.oid, 100, 1000)), "partial:c200 c300");  // c100 itself was asked for
    EXPECT_EQ(answer(f.store.range(f.oid, 101, 1000)), "c200 c300");          // nothing asked for is gone
    EXPECT_EQ(answer(f.store.range(f.oid, 0, 1000, By::data)), "partial:c300 c200");
    EXPECT_EQ(answer(f.store.range(f.oid, 11, 1000, By::data)), "c300 c200");
    EXPECT_EQ(answer(f.store.range(f.oid, 0, 150)), "evicted");  // only the evicted part
}

/// What a store holding `window` of the samples a test commits must answer, found by scanning
/// them: the reference the scan tests hold the store's searches to.
struct Scan
{
    struct Sample
    {
        uint64_t commit, data;
    };
    uint64_t window;
    std::vector<Sample> all;
    size_t first_held = 0;
    uint64_t max_evicted[2] = {0, 0};  // by commit, by data
    bool any_evicted = false;

    static uint64_t key(const Sample& s, By by) { return by == By::commit ? s.commit : s.data; }
    /// Commits the sample to the store and to the scan's own account.
    void commit(Store& store, Oid oid, Sample s)
    {
        const uint8_t byte = uint8_t(all.size());
        ASSERT_EQ(store.commit(oid, {s.data, s.data, 0, &byte, 1}, s.commit), s.commit);
        all.push_back(s);
        for (; all[first_held].commit + window < s.commit; ++first_held) {  // evicted by this commit
            any_evicted = true;
            for (By by : {By::commit, By::data}) max_evicted[int(by)] = std::max(max_evicted[int(by)], key(all[first_held], by));
        }
    }
    /// Checks `at`, `older`, `younger` and a range [t, t + span) by `by` against the scan.
    void check(const Store& store, Oid oid, uint64_t t, By by, uint64_t span) const
    {
        // The held samples sorted by (time, commit): the order the store answers in.
        std::vector<Sample> held(all.begin() + ptrdiff_t(first_held), all.end());
        std::stable_sort(held.begin(), held.end(), [by](const Sample& a, const Sample& b) { return key(a, by) < key(b, by); });
        auto commit_of = [](const Found& f) { return f.ok() ? f.sample.commit_ns : 0; };
        uint64_t at = 0, older = 0, younger = 0;
        std::vector<uint64_t> want, got;
        for (const Sample& s : held) {
            if (key(s, by) <= t) at = s.commit;
            if (key(s, by) < t) older = s.commit;
            if (key(s, by) > t && !younger) younger = s.commit;
            if (key(s, by) >= t && key(s, by) < t + span) want.push_back(s.commit);
        }
        const char* how = by == By::commit ? " by commit" : " by data";
        EXPECT_EQ(commit_of(store.at(oid, t, by)), at) << "at " << t << how;
        EXPECT_EQ(commit_of(store.older(oid, t, by)), older) << "older " << t << how;
        const Found y = store.younger(oid, t, by);
        if (any_evicted && t < max_evicted[int(by)]) EXPECT_EQ(y.status, Status::evicted) << "younger " << t << how;
        else EXPECT_EQ(commit_of(y), younger) << "younger " << t << how;
        for (const StoredSample& x : store.range(oid, t, t + span, by).samples) got.push_back(x.commit_ns);
        EXPECT_EQ(got, want) << "range from " << t << how;
    }
};

TEST(StoreQuery, DataTimeQueriesMatchAScanOfTheHeldSamplesWhileLateSamplesComeAndAreEvicted)
{
    // 4000 samples, a window of 300 of them. Data times run ahead with the commits except in
    // the middle stretch, where one sample in ten is late by up to 50 cycles; then they are in
    // order again long enough for every late one to be evicted. After every sample, data-time
    // `at`, `older`, `younger` and `range` are checked against a scan of what the window holds.
    constexpr uint64_t kCycle = 10, kHeld = 300;
    Scan scan{kHeld * kCycle - 1};
    Store store{StoreOptions{{scan.window, 1ull << 30}, 1ull << 30}};
    const Oid oid = store.add_object({.topic = "t"});
    std::mt19937_64 rng(7);
    for (uint64_t n = 1; n <= 4000 && !HasFailure(); ++n) {
        const uint64_t commit = n * kCycle;
        uint64_t data = 1'000 + commit;
        if (n > 1000 && n < 2000 && rng() % 10 == 0) data -= kCycle * (1 + rng() % 50);
        scan.commit(store, oid, {commit, data});
        for (int q = 0; q < 3; ++q) {
            scan.check(store, oid, 1'000 + commit - rng() % (kHeld * kCycle + 100 * kCycle) + rng() % (5 * kCycle), By::data, 40 * kCycle);
        }
    }
}

TEST(StoreQuery, QueriesMatchAScanWhenSamplesComeInBurstsAndPauses)
{
    // The searches first look where evenly spaced samples would lie. Here samples come in bursts
    // 1 ns apart with pauses of up to 100,000 ns between, data times repeat within a burst and
    // some come late, so that first look is mostly wrong: the answers must not be.
    Scan scan{400'000};
    Store store{StoreOptions{{scan.window, 1ull << 30}, 1ull << 30}};
    const Oid oid = store.add_object({.topic = "t"});
    std::mt19937_64 rng(11);
    uint64_t commit = 1'000'000;
    for (int n = 1; n <= 3000 && !HasFailure(); ++n) {
        commit += rng() % 8 ? 1 : 1 + rng() % 100'000;
        const uint64_t data = commit / 4 * 4 - (rng() % 20 ? 0 : rng() % 50'000);
        scan.commit(store, oid, {commit, data});
        for (By by : {By::commit, By::data}) {
            for (int q = 0; q < 2; ++q) scan.check(store, oid, commit + 1'000 - rng() % (scan.window + 100'000), by, 20'000);
        }
    }
    EXPECT_TRUE(scan.any_evicted);
}

TEST(StoreQuery, CopiesCarryTheirSamplesBytesWhileSizesChangeAndSamplesAreEvicted)
{
    // A copying query fetches the payload where it most likely lies while samples are all of one
    // size. Here the size stays the same for a while, changes, and varies; every copy must
    // still be its own sample's bytes, whichever sample the query named.
    Store store{StoreOptions{{5'000, 1ull << 30}, 1ull << 30}};
    const Oid oid = store.add_object({.topic = "t"});
    auto bytes_of = [](uint64_t commit, size_t size) {
        std::vector<uint8_t> b(size);
        for (size_t i = 0; i < size; ++i) b[i] = uint8_t(commit * 31 + i);
        return b;
    };
    std::map<uint64_t, size_t> size_of;  // commit -> payload size
    std::mt19937_64 rng(5);
    for (uint64_t n = 1; n <= 4500 && !HasFailure(); ++n) {
        const uint64_t commit = n * 10;
        const size_t size = n < 2000 ? 150 : n < 3000 ? 151 : n < 4000 ? 1 + rng() % 400 : 20'000;
        const std::vector<uint8_t> b = bytes_of(commit, size);
        ASSERT_EQ(store.commit(oid, {commit, commit, 0, b.data(), b.size()}, commit), commit);
        size_of[commit] = size;
        for (int q = 0; q < 4; ++q) {
            const uint64_t t = commit + 100 - rng() % 6'000;
            for (const Found& f : {store.at(oid, t, By::commit), store.older(oid, t, By::data), store.younger(oid, t, By::commit),
                                   store.latest(oid)}) {
                if (!f.ok()) continue;
                ASSERT_EQ(f.sample.payload, bytes_of(f.sample.commit_ns, size_of.at(f.sample.commit_ns))) << "sample c" << f.sample.commit_ns;
            }
        }
    }
}

TEST(StoreQuery, UnknownObjectIsNamedAsSuch)
{
    Store store;
    EXPECT_EQ(store.at(42, 1).status, Status::unknown_object);
    EXPECT_FALSE(store.info(42));
}

}  // namespace

TEST(StoreGaps, SamplesLostBeforeOneMakeItsPredecessorsSuccessorAGapAndAreCounted)
{
    Store sut{StoreOptions{{1'000'000, 1 << 20}, 1 << 30}};
    const Oid oid = sut.add_object({.topic = "vehicleState", .key = "5", .created_ts = 1});
    const uint8_t byte = 7;
    sut.commit(oid, {10, 10, 10, &byte, 1}, 100);
    sut.commit(oid, {20, 20, 20, &byte, 1}, 200);
    sut.commit(oid, {50, 50, 50, &byte, 1, 2}, 500);  // two samples never arrived before this one
    sut.commit(oid, {60, 60, 60, &byte, 1}, 600);
    EXPECT_EQ(sut.successor(oid, 100, std::chrono::nanoseconds(0)).status, Status::ok);
    EXPECT_EQ(sut.successor(oid, 200, std::chrono::nanoseconds(0)).status, Status::gap);
    EXPECT_EQ(sut.successor(oid, 500, std::chrono::nanoseconds(0)).sample.commit_ns, 600u);
    EXPECT_EQ(sut.info(oid)->samples_lost, 2u);
    EXPECT_EQ(sut.stats().lost, 2u);
    EXPECT_EQ(sut.range(oid, 0, 1000).lost, 2u);
    EXPECT_EQ(sut.range(oid, 0, 300).lost, 0u);  // the hole lies after the last sample it returns
    EXPECT_EQ(sut.range(oid, 500, 700).lost, 0u);  // ... or before the first
    EXPECT_EQ(sut.range(oid, 10, 60, By::data).lost, 2u);
}
