// Two recordings compared sample for sample (cpm history --file A diff B): equal runs are
// identical whatever their commit times; the first difference of each topic and key is named,
// down to the field.
#include <cpm/rtdb/Diff.hpp>
#include <cpm/rtdb/Recording.hpp>
#include <cpm/rtdb/Store.hpp>

#include <VehicleStatePubSubTypes.h>

#include <cpm_test/TempDir.hpp>

#include <gtest/gtest.h>

#include <functional>

#include "serialized.hpp"

using namespace cpm::rtdb;

namespace {

struct Variant
{
    double car5_x_at_3 = 0.3;  ///< car 5's pose.x in its sample 3
    int car6_samples = 5;
    bool command = false;      ///< also a vehicleCommandDirect/5 object
    uint64_t commit_offset = 0;
};

std::string a_run(const cpm_test::TempDir& dir, const std::string& name, const Variant& v)
{
    const std::string path = dir.file(name + ".db");
    Store store;
    RecordingWriter writer(path);
    const auto add = [&](ObjectInfo info) {
        const Oid oid = store.add_object(std::move(info));
        writer.object_added(*store.info(oid));
        return oid;
    };
    uint64_t now = 1'000'000'000 + v.commit_offset;
    const auto commit = [&](Oid oid, uint64_t data_ns, const std::vector<uint8_t>& payload) {
        Incoming in{data_ns, data_ns, 0, payload.data(), payload.size(), 0};
        writer.sample_committed(oid, in, store.commit(oid, in, now += 1000));
    };
    const Oid car5 = add({.topic = "vehicleState", .key = "5", .type_name = "VehicleState"});
    const Oid car6 = add({.topic = "vehicleState", .key = "6", .type_name = "VehicleState"});
    const Oid clock = add({.topic = "readyStatus", .key = "fsm_node_5", .type_name = "ReadyStatus"});
    for (int i = 0; i < 5; ++i) {
        VehicleState s;
        s.vehicle_id(5);
        s.pose().x(i == 3 ? v.car5_x_at_3 : 0.1 * i);
        commit(car5, 20'000'000ull * i, serialized<VehicleStatePubSubType>(s));
        if (i < v.car6_samples) {
            s.vehicle_id(6);
            s.pose().x(1.0);
            commit(car6, 20'000'000ull * i, serialized<VehicleStatePubSubType>(s));
        }
        commit(clock, v.commit_offset + i, {uint8_t(v.commit_offset), 1, 2});  // the clock's wall times differ from run to run
    }
    if (v.command) commit(add({.topic = "vehicleCommandDirect", .key = "5", .type_name = "VehicleCommandDirect"}), 0, {0, 1, 0, 0});
    writer.close();
    return path;
}

}  // namespace

TEST(Diff, TwoEqualRunsAreIdenticalWhateverTheirCommitTimesAndTheClocksTraffic)
{
    cpm_test::TempDir dir;
    const auto a = load_recording(a_run(dir, "a", {}));
    const auto b = load_recording(a_run(dir, "b", {.commit_offset = 777'000}));
    const auto result = diff_recordings(a, b);
    EXPECT_TRUE(result.identical()) << (result.differences.empty() ? "" : result.differences[0].what);
    EXPECT_EQ(result.objects, 2u) << "vehicleState/5 and /6; readyStatus left out";
    EXPECT_EQ(result.samples, 10u);
    const auto all = diff_recordings(a, b, DiffOptions{.exclude = {}});
    ASSERT_EQ(all.differences.size(), 1u) << "the clock's traffic, when asked for";
    EXPECT_EQ(all.differences[0].topic, "readyStatus");
}

TEST(Diff, TheFirstDifferenceOfEachTopicAndKeyIsNamedDownToTheField)
{
    cpm_test::TempDir dir;
    const auto a = load_recording(a_run(dir, "a", {}));
    const auto b = load_recording(a_run(dir, "b", {.car5_x_at_3 = 0.3125, .car6_samples = 4, .command = true}));
    const auto result = diff_recordings(a, b);
    ASSERT_EQ(result.differences.size(), 3u);  // by topic, then key
    const auto& command = result.differences[0];
    EXPECT_EQ(command.topic, "vehicleCommandDirect");
    EXPECT_EQ(command.what, "only in B (A has no vehicleCommandDirect/5)");
    const auto& car5 = result.differences[1];
    EXPECT_EQ(car5.topic + "/" + car5.key, "vehicleState/5");
    EXPECT_EQ(car5.index, 3u);
    EXPECT_EQ(car5.data_ns_a, 60'000'000u);
    EXPECT_EQ(car5.what, "pose.x: 0.3 in A, 0.3125 in B");
    const auto& car6 = result.differences[2];
    EXPECT_EQ(car6.key, "6");
    EXPECT_EQ(car6.index, 4u);
    EXPECT_EQ(car6.what, "A has 5 samples, B 4; the first extra one at data time 0.080000000 s");
    EXPECT_EQ(result.samples, 3u + 4u) << "car 5's first three, car 6's first four";
    // Only the topics asked for.
    EXPECT_EQ(diff_recordings(a, b, DiffOptions{.topics = {"vehicleCommandDirect"}}).differences.size(), 1u);
}
