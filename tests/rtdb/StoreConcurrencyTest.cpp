// The store under a concurrent writer: snapshot consistency, wait_next/successor wake-ups,
// timeouts and gaps, retention by time and by bytes; and the object registry.
#include <cpm/Error.hpp>
#include <cpm/rtdb/Store.hpp>

#include <gtest/gtest.h>

#include <malloc.h>

#include <atomic>
#include <functional>
#include <regex>
#include <thread>

using namespace cpm::rtdb;
using namespace std::chrono_literals;

namespace {

uint64_t now_ns() { return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch()).count(); }

/// Runs `change` on another thread 50 ms from now, while the caller waits for it.
std::thread soon(std::function<void()> change)
{
    return std::thread([change = std::move(change)] {
        std::this_thread::sleep_for(50ms);
        change();
    });
}

void put(Store& s, Oid oid, uint64_t data, const std::vector<uint8_t>& payload, uint64_t now)
{
    s.commit(oid, {data, data, 0, payload.data(), payload.size()}, now);
}

TEST(StoreSnapshot, IsOneConsistentCutUnderAConcurrentWriter)
{
    Store store;
    const Oid a = store.add_object({.topic = "a", .type_name = "T"});
    const Oid b = store.add_object({.topic = "b", .type_name = "T"});
    std::atomic<bool> stop{false};
    // Each round writes generation g to a, then to b, each payload 200 bytes of g.
    std::thread writer([&] {
        for (uint64_t g = 1; !stop; ++g) {
            std::vector<uint8_t> p(200, uint8_t(g));
            put(store, a, g, p, now_ns());
            put(store, b, g, p, now_ns());
        }
    });
    int checked = 0;
    uint64_t first_generation = 0, last_generation = 0;
    for (int i = 0; checked < 10000 && i < 100'000'000; ++i) {
        auto cut = store.snapshot(~0ull, {a, b});
        if (!cut[0].ok() || !cut[1].ok()) continue;
        const uint64_t ga = cut[0].sample.data_ns, gb = cut[1].sample.data_ns;
        // b is written after a: a consistent cut has a == b or a == b + 1.
        ASSERT_TRUE(ga == gb || ga == gb + 1) << "a " << ga << " b " << gb;
        for (auto& f : cut) {
            for (uint8_t byte : f.sample.payload) ASSERT_EQ(byte, uint8_t(f.sample.data_ns)) << "torn payload";
        }
        if (!first_generation) first_generation = ga;
        last_generation = ga;
        ++checked;
    }
    stop = true;
    writer.join();
    EXPECT_EQ(checked, 10000);
    EXPECT_GT(last_generation - first_generation, 100u);  // the writer really ran alongside
}

TEST(StoreWait, WaitNextWakesOnTheNextCommitAndReturnsTheNewest)
{
    Store store;
    const Oid oid = store.add_object({.topic = "t"});
    put(store, oid, 1, {1}, 1000);
    std::thread writer = soon([&] { put(store, oid, 2, {2}, 2000); });
    auto f = store.wait_next(oid, 1000, 10s);
    writer.join();
    ASSERT_TRUE(f.ok()) << to_string(f.status);
    EXPECT_EQ(f.sample.commit_ns, 2000u);
    EXPECT_EQ(f.sample.payload, std::vector<uint8_t>{2});
    // Something newer than `after` already there: no wait, the newest.
    put(store, oid, 3, {3}, 3000);
    EXPECT_EQ(store.wait_next(oid, 1000, 0ms).sample.commit_ns, 3000u);
    EXPECT_EQ(store.wait_next(oid, 3000, 30ms).status, Status::timeout);
    EXPECT_EQ(store.wait_next(999, 0, 30ms).status, Status::unknown_object);
}

TEST(StoreWait, SuccessorIsExactlyTheNextOrAGapWhenItWasEvicted)
{
    Store store{StoreOptions{{1000, 1 << 20}, 1 << 30}};
    const Oid oid = store.add_object({.topic = "t"});
    for (uint64_t c : {100, 200, 300}) put(store, oid, c, {uint8_t(c / 100)}, c);
    EXPECT_EQ(store.successor(oid, 100, 0ms).sample.commit_ns, 200u);  // not the newest
    EXPECT_EQ(store.successor(oid, 150, 0ms).sample.commit_ns, 200u);
    EXPECT_EQ(store.successor(oid, 300, 20ms).status, Status::timeout);
    std::thread writer = soon([&] { put(store, oid, 4, {4}, 400); });
    EXPECT_EQ(store.successor(oid, 300, 10s).sample.commit_ns, 400u);
    writer.join();
    store.expire(1250);  // 100 and 200 leave the 1000 ns window
    EXPECT_EQ(store.successor(oid, 100, 0ms).status, Status::gap);  // 200 was next, and is gone
    EXPECT_EQ(store.successor(oid, 200, 0ms).sample.commit_ns, 300u);
}

TEST(StoreWait, SuccessorOnAnEmptyObjectWaitsForTheFirstSample)
{
    Store store;
    const Oid oid = store.add_object({.topic = "t"});
    EXPECT_EQ(store.successor(oid, 0, 20ms).status, Status::timeout);
    std::thread writer = soon([&] { put(store, oid, 1, {1}, 10); });
    EXPECT_EQ(store.successor(oid, 0, 10s).sample.commit_ns, 10u);
    writer.join();
}

TEST(StoreRetention, KeepsTheTimeWindowOfEachTopic)
{
    Store store;
    store.set_retention("fast", {1'000, 1 << 20});
    const Oid fast = store.add_object({.topic = "fast"});
    const Oid slow = store.add_object({.topic = "slow"});
    EXPECT_EQ(store.info(fast)->history_interval_ns, 1'000u);
    EXPECT_EQ(store.info(slow)->history_interval_ns, 10'000'000'000u);  // the default, 10 s
    for (uint64_t t = 1; t <= 5000; ++t) {
        put(store, fast, t, {1}, t);
        put(store, slow, t, {1}, t);
    }
    // On commit the window is kept relative to the newest sample.
    EXPECT_EQ(store.info(fast)->samples_held, 1001u);
    EXPECT_EQ(store.info(slow)->samples_held, 5000u);
    EXPECT_EQ(store.at(fast, 3000).status, Status::evicted);
    store.expire(20'000'000'000ull);
    EXPECT_EQ(store.info(slow)->samples_held, 0u);
    EXPECT_EQ(store.latest(slow).status, Status::evicted);
}

TEST(StoreRetention, PayloadMemoryIsGivenBackWhenAnEmptiedObjectTakesLargerSamples)
{
    // A small sample, evicted by the window, then 1 MiB samples each evicting the one before:
    // the store must hold about one of them, not every one it was ever given.
    Store store;
    store.set_retention("camera", {1'000, 1ull << 32});
    const Oid oid = store.add_object({.topic = "camera"});
    put(store, oid, 1, {1}, 1);
    const std::vector<uint8_t> frame(1 << 20, 9);
    auto heap = [] {
        const auto m = mallinfo2();
        return m.uordblks + m.hblkhd;  // in the arena and mapped apart (large blocks)
    };
    const size_t heap_before = heap();
    for (uint64_t i = 1; i <= 100; ++i) put(store, oid, i * 10'000, frame, i * 10'000);
    const size_t grown = heap() - heap_before;
    EXPECT_EQ(store.info(oid)->samples_held, 1u);
    EXPECT_EQ(store.latest(oid).sample.payload, frame);
    EXPECT_LT(grown, size_t(4 << 20)) << "heap grew by " << grown << " bytes for one held 1 MiB sample";
}

TEST(StoreRetention, AFloodOfLargeSamplesStaysWithinTheByteBudgets)
{
    StoreOptions options;
    options.default_retention = {~0ull / 2, 4 << 20};  // 4 MiB per topic, no time limit
    options.max_bytes_total = 6 << 20;                 // 6 MiB in all
    Store store(options);
    const Oid a1 = store.add_object({.topic = "camera", .key = "1"});
    const Oid a2 = store.add_object({.topic = "camera", .key = "2"});
    const Oid b = store.add_object({.topic = "lidar"});
    std::vector<uint8_t> big(100'000, 7);
    uint64_t t = 1;
    for (int i = 0; i < 300; ++i) {  // 30 MB into each topic
        put(store, a1, t, big, t);
        ++t;
        put(store, a2, t, big, t);
        ++t;
        put(store, b, t, big, t);
        ++t;
        auto s = store.stats();
        ASSERT_LE(s.bytes, 6u << 20);
        ASSERT_LE(store.info(a1)->bytes_held + store.info(a2)->bytes_held, 4u << 20);
    }
    auto s = store.stats();
    EXPECT_GT(s.bytes, 5u << 20);  // it still uses what it may
    EXPECT_GT(s.evicted, 800u);
    // The oldest went first: both camera instances keep their recent past.
    EXPECT_GT(store.info(a1)->samples_held, 5u);
    EXPECT_GT(store.info(a2)->samples_held, 5u);
    EXPECT_TRUE(store.latest(a1).ok());
}

TEST(StoreRegistry, SearchesByNameTypeParentCreatorAndAliveAt)
{
    Store store;
    const Oid proc = store.add_object({.kind = ObjectKind::process, .name = "vehicle_bridge_3", .type_name = "participant",
                                       .creator = "vehicle_bridge_3", .creator_guid = "01.0f.aa", .created_ts = 100});
    const Oid state3 = store.add_object({.topic = "vehicleState", .key = "3", .type_name = "VehicleState", .parent = proc,
                                         .creator = "vehicle_bridge_3", .created_ts = 110});
    const Oid ranges3 = store.add_object({.topic = "rangeSensors", .key = "3", .type_name = "RangeSensors", .parent = proc,
                                          .creator = "vehicle_bridge_3", .created_ts = 120});
    const Oid state4 = store.add_object({.topic = "vehicleState", .key = "4", .type_name = "VehicleState",
                                         .creator = "vehicle_bridge_4", .created_ts = 300});
    store.mark_deleted(ranges3, 200);
    auto oids = [](const std::vector<ObjectInfo>& v) {
        std::vector<Oid> o;
        for (auto& i : v) o.push_back(i.oid);
        return o;
    };
    EXPECT_EQ(store.info(state3)->name, "vehicleState/3");
    EXPECT_EQ(oids(store.search({.name_regex = "VEHICLESTATE"})), (std::vector<Oid>{state3, state4}));
    EXPECT_EQ(oids(store.search({.name_regex = "/3$"})), (std::vector<Oid>{state3, ranges3}));
    EXPECT_EQ(oids(store.search({.type_name = "RangeSensors"})), (std::vector<Oid>{ranges3}));
    EXPECT_EQ(oids(store.search({.parent = proc})), (std::vector<Oid>{state3, ranges3}));
    EXPECT_EQ(oids(store.search({.creator = "01.0f.aa"})), (std::vector<Oid>{proc}));
    EXPECT_EQ(oids(store.search({.creator = "vehicle_bridge_4"})), (std::vector<Oid>{state4}));
    EXPECT_EQ(oids(store.search({.alive_at = 150})), (std::vector<Oid>{proc, state3, ranges3}));
    EXPECT_EQ(oids(store.search({.alive_at = 250})), (std::vector<Oid>{proc, state3}));
    EXPECT_EQ(oids(store.search({.name_regex = "state", .alive_at = 350})), (std::vector<Oid>{state3, state4}));
    EXPECT_EQ(oids(store.search({.kind = ObjectKind::process})), (std::vector<Oid>{proc}));
    EXPECT_THROW(store.search({.name_regex = "(unclosed"}), cpm::Error);

    auto changes = store.changes_since(115);
    EXPECT_EQ(oids(changes.created), (std::vector<Oid>{ranges3, state4}));
    EXPECT_EQ(oids(changes.deleted), (std::vector<Oid>{ranges3}));
    EXPECT_EQ(store.find("vehicleState", "4"), state4);
    EXPECT_FALSE(store.find("vehicleState", "5"));
}

TEST(StoreRegistry, WaitForObjectWakesWhenOneAppearsAndTimesOutOtherwise)
{
    Store store;
    EXPECT_FALSE(store.wait_for_object({.name_regex = "^camera"}, 20ms));
    std::thread creator = soon([&] {
        store.add_object({.topic = "other"});
        store.add_object({.topic = "cameraFrames", .type_name = "Image"});
    });
    auto found = store.wait_for_object({.name_regex = "^camera"}, 10s);
    creator.join();
    ASSERT_TRUE(found);
    EXPECT_EQ(found->type_name, "Image");
}

TEST(StoreRegistry, DeletedObjectsStayReadableForTheirWindowThenArePurged)
{
    Store store;
    store.set_retention("t", {1'000, 1 << 20});
    const Oid oid = store.add_object({.topic = "t", .created_ts = 1});
    put(store, oid, 1, {9}, 100);
    store.mark_deleted(oid, 500);
    store.expire(1'400);
    ASSERT_TRUE(store.info(oid));
    EXPECT_EQ(store.info(oid)->deleted_ts, 500u);
    EXPECT_EQ(store.latest(oid).status, Status::evicted);  // its sample left the window at 1100
    EXPECT_EQ(store.search({.alive_at = 600}).size(), 0u);
    EXPECT_EQ(store.search({.alive_at = 400}).size(), 1u);
    store.expire(1'501);
    EXPECT_FALSE(store.info(oid));
    EXPECT_EQ(store.latest(oid).status, Status::unknown_object);
    EXPECT_EQ(store.stats().objects, 0u);
    EXPECT_EQ(store.stats().purged_objects, 1u);
}

TEST(StoreRegistry, APurgedObjectsOidStaysUnknownWhenANewObjectTakesItsPlace)
{
    Store store;
    store.set_retention("t", {1'000, 1 << 20});
    const Oid old_oid = store.add_object({.topic = "t", .key = "1", .created_ts = 1});
    put(store, old_oid, 1, {1}, 100);
    store.mark_deleted(old_oid, 200);
    store.expire(1'201);
    const Oid new_oid = store.add_object({.topic = "t", .key = "1", .created_ts = 1'300});
    put(store, new_oid, 2, {2}, 1'400);
    EXPECT_NE(new_oid, old_oid);
    EXPECT_EQ(store.latest(old_oid).status, Status::unknown_object);
    EXPECT_FALSE(store.info(old_oid));
    EXPECT_EQ(store.view(old_oid, Which::latest, 0, By::commit, [](const SampleView&) { ADD_FAILURE() << "purged object answered"; }),
              Status::unknown_object);
    EXPECT_EQ(store.snapshot(1'500, {old_oid, new_oid})[0].status, Status::unknown_object);
    EXPECT_EQ(store.latest(new_oid).sample.payload, std::vector<uint8_t>{2});
    EXPECT_EQ(store.find("t", "1"), new_oid);
    EXPECT_EQ(store.stats().objects, 1u);
}

TEST(StoreRegistry, ReadersNeverSeeAnotherObjectsSamplesWhileObjectsArePurgedAndReplaced)
{
    // The ingest thread keeps creating an object, filling it with payloads of its own byte,
    // deleting and purging it; readers asking any oid handed out so far get that object's
    // bytes, no sample yet, or unknown_object, never a later object's.
    // How far each side gets depends on scheduling, so the readers go on until they have asked
    // kQueries times *and* once more for every one of the kObjects oids the ingest hands out.
    constexpr size_t kObjects = 2'000;
    constexpr uint64_t kQueries = 200'000;
    Store store;
    store.set_retention("t", {10, 1 << 20});
    std::atomic<bool> stop{false};
    std::vector<Oid> oids(1);  // oids[g]: the object of generation g; filled before it is published
    oids.reserve(kObjects + 1);  // never moves while readers look
    std::atomic<size_t> published{0};
    std::atomic<uint64_t> live_reads{0};  // answers with a sample
    std::thread ingest([&] {
        uint64_t t = 1'000;
        for (uint8_t g = 1; !stop; ++g) {
            const Oid oid = store.add_object({.topic = "t", .key = std::to_string(g), .created_ts = t});
            if (published < kObjects) {
                oids.push_back(oid);  // readers only look at 1..published
                published = oids.size() - 1;
            }
            const uint8_t own = uint8_t(oid >> 32) ^ uint8_t(oid);  // the byte of this oid
            for (int i = 0; i < 20; ++i, ++t) put(store, oid, t, std::vector<uint8_t>(64, own), t);
            // While it hands out the objects the readers ask about, it gives them a moment to
            // read a live one (up to 1 ms), so that the race is really run, not only the purge.
            const uint64_t reads_before = live_reads;
            const auto until = std::chrono::steady_clock::now() + 1ms;
            while (published < kObjects && live_reads == reads_before && std::chrono::steady_clock::now() < until)
                std::this_thread::yield();
            store.mark_deleted(oid, t);
            store.expire(t += 20);  // purged: its slot is free for the next
        }
    });
    uint64_t seen = 0, unknown = 0, empty = 0, asked = 0, asked_of_all = 0;
    const auto deadline = std::chrono::steady_clock::now() + 60s;
    while (asked < kQueries || asked_of_all < kObjects) {
        const size_t n = published;
        if (n == 0) continue;
        if (asked % 4096 == 0 && std::chrono::steady_clock::now() > deadline) break;
        if (n == kObjects) ++asked_of_all;
        const Oid oid = oids[1 + asked++ % n];
        const uint8_t own = uint8_t(oid >> 32) ^ uint8_t(oid);
        const Status st = store.view(oid, Which::latest, 0, By::commit, [&](const SampleView& v) {
            for (size_t i = 0; i < v.size; ++i) ASSERT_EQ(v.data[i], own) << "oid " << oid << " answered with another object's bytes";
        });
        (st == Status::ok ? seen : st == Status::unknown_object ? unknown : empty)++;
        if (st == Status::ok) ++live_reads;
    }
    stop = true;
    ingest.join();
    ASSERT_EQ(published.load(), kObjects) << "the ingest thread handed out too few objects within 60 s";
    EXPECT_EQ(seen + unknown + empty, asked);
    EXPECT_GT(seen, 0u) << "no reader ever saw a sample: the race the test is about never happened";
    // The last kObjects questions asked for every oid once; all but the newest were purged.
    EXPECT_GE(unknown, kObjects - 1);
}

}  // namespace
