// cpm::rtdb::HistoryService in this process with a further IngestSink (where a recording is fed
// from): the sink gets every object, sample and deletion the store gets, with the same oids and
// commit times, from a real writer over DDS.
#include <cpm/Participant.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/rtdb/HistoryService.hpp>
#include <cpm/stamp_message.hpp>

#include <cpm_test/Dds.hpp>
#include <cpm_test/Isolation.hpp>

#include <VehicleState.h>

#include <gtest/gtest.h>

#include <map>
#include <mutex>
#include <set>

using namespace std::chrono_literals;
using cpm::rtdb::ObjectInfo;
using cpm::rtdb::Oid;

namespace {

struct Collector : cpm::rtdb::IngestSink
{
    std::mutex m;
    std::map<Oid, ObjectInfo> objects;
    std::map<Oid, std::vector<uint64_t>> commits;
    std::map<Oid, std::vector<size_t>> payload_sizes;  // to see the bytes came along
    std::set<Oid> deleted;

    void object_added(const ObjectInfo& info) override
    {
        std::lock_guard lock(m);
        objects[info.oid] = info;
    }
    void sample_committed(Oid oid, const cpm::rtdb::Incoming& s, uint64_t commit_ns) override
    {
        std::lock_guard lock(m);
        commits[oid].push_back(commit_ns);
        payload_sizes[oid].push_back(s.size);
    }
    void object_deleted(Oid oid, uint64_t) override
    {
        std::lock_guard lock(m);
        deleted.insert(oid);
    }
};

cpm::ParticipantOptions udp_only()
{
    auto o = cpm_test::isolated_options();
    o.shared_memory = false;
    return o;
}

}  // namespace

TEST(HistoryServiceSink, GetsEveryObjectSampleAndDeletionTheStoreGets)
{
    auto sink = std::make_shared<Collector>();
    cpm::rtdb::ServiceOptions options;
    options.participant = udp_only();
    options.include = {"vehicleState"};
    options.sinks = {sink};
    cpm::rtdb::HistoryService service(options);

    constexpr int kSamples = 20;
    {
        cpm::Participant car(udp_only());
        cpm::Writer<VehicleState> writer(car, "vehicleState", {.reliable = true, .history_depth = kSamples, .transient_local = true});
        ASSERT_TRUE(cpm_test::wait_until([&] { return service.counters().topics == 1; }, 10s));
        ASSERT_TRUE(writer.wait_for_matched(1, 10s));
        for (int i = 0; i < kSamples; ++i) {
            VehicleState s;
            s.vehicle_id(4);
            s.speed(0.1 * i);
            cpm::stamp_message(s, cpm::get_time_ns(), 0);
            ASSERT_TRUE(writer.write(s));
        }
        ASSERT_TRUE(cpm_test::wait_until([&] { return service.counters().received >= kSamples; }, 10s))
            << service.counters().received;
    }  // the writer's process part leaves: the instance is deleted

    const auto oid = service.store().find("vehicleState", "4");
    ASSERT_TRUE(oid);
    ASSERT_TRUE(cpm_test::wait_until([&] {
        std::lock_guard lock(sink->m);
        return sink->deleted.count(*oid) != 0;
    }, 15s)) << "the sink never heard that the writer left";
    const auto held = service.store().range(*oid, 0, UINT64_MAX);
    std::lock_guard lock(sink->m);
    ASSERT_EQ(sink->objects.count(*oid), 1u);
    EXPECT_EQ(sink->objects[*oid].name, "vehicleState/4");
    EXPECT_EQ(sink->objects[*oid].type_name, "VehicleState");
    ASSERT_EQ(held.samples.size(), size_t(kSamples));
    ASSERT_EQ(sink->commits[*oid].size(), size_t(kSamples));
    for (size_t i = 0; i < held.samples.size(); ++i) {
        EXPECT_EQ(sink->commits[*oid][i], held.samples[i].commit_ns) << i;
        EXPECT_EQ(sink->payload_sizes[*oid][i], held.samples[i].payload.size()) << i;
    }
    EXPECT_TRUE(service.store().info(*oid)->deleted_ts != 0);
}
