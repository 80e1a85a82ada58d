// cpm (Fast DDS) and a Cyclone DDS program built from the same IDL exchange VehicleState
// both ways, on loopback only. Transient-local on both sides: each side may see the match
// before the other does, and a volatile reader may then skip what was written before.
#include <cpm/HistoryClient.hpp>
#include <cpm/MultiVehicleReader.hpp>
#include <cpm/Writer.hpp>
#include <cpm_test/Dds.hpp>
#include <cpm_test/Isolation.hpp>
#include <cpm_test/Process.hpp>

#include <VehicleState.h>

#include <gtest/gtest.h>

#include <set>
#include <sstream>

using namespace std::chrono_literals;

namespace {

// Cyclone on loopback only, unicast discovery to this host's well-known ports.
const std::string kCycloneConfig = "CYCLONEDDS_URI=file://" CPM_CYCLONE_LOOPBACK_XML;

std::vector<std::string> peer_env(const std::string& topic) { return {kCycloneConfig, "CPM_INTEROP_TOPIC=" + topic}; }

}  // namespace

TEST(CycloneInterop, CyclonePublisherIsReadByMultiVehicleReaderWithKeysAndStamps)
{
    cpm::Participant participant(cpm_test::isolated_options());
    const std::string topic = cpm_test::unique_topic("vehicleState");
    cpm::MultiVehicleReader<VehicleState> sut(participant, topic, std::vector<uint8_t>{1, 2},
                                              {.reliable = true, .keep_all = true, .transient_local = true});
    constexpr int kCount = 20;

    cpm_test::Process peer({cpm_test::built_program("cyclone_peer"), "pub", std::to_string(kCount), "1", "2"},
                           peer_env(topic));
    ASSERT_EQ(peer.wait(30000ms), 0) << "the Cyclone publisher failed (no match or no acknowledgement)";

    // The newest sample k = kCount-1 of vehicle id has create = 1000 k + id, valid_after = create + 60.
    const uint64_t t_now = 1000ull * (kCount - 1) + 2 + 60;
    auto results = sut.get_samples(t_now);
    for (uint8_t id : {1, 2}) {
        const auto& r = results.at(id);
        ASSERT_TRUE(r.valid) << "nothing valid from vehicle " << int(id);
        EXPECT_EQ(r.sample.vehicle_id(), id);
        EXPECT_EQ(r.sample.header().create_stamp().nanoseconds(), 1000ull * (kCount - 1) + id);
        EXPECT_EQ(r.sample.header().valid_after_stamp().nanoseconds(), 1000ull * (kCount - 1) + id + 60);
        EXPECT_EQ(r.sample.pose().x(), kCount - 1);
        EXPECT_DOUBLE_EQ(r.sample.speed(), 0.5 * id);
        EXPECT_EQ(r.age_ns, t_now - r.sample.header().valid_after_stamp().nanoseconds());
    }
}

TEST(CycloneInterop, CpmWriterIsReadByCycloneReader)
{
    cpm::Participant participant(cpm_test::isolated_options());
    const std::string topic = cpm_test::unique_topic("vehicleState");
    constexpr int kPerVehicle = 5;
    cpm_test::Process peer({cpm_test::built_program("cyclone_peer"), "sub", std::to_string(2 * kPerVehicle)},
                           peer_env(topic));
    ASSERT_TRUE(cpm_test::wait_until([&] { return peer.output().find("ready") != std::string::npos; }, 10000ms));
    cpm::Writer<VehicleState> sut(participant, topic, {.reliable = true, .keep_all = true, .transient_local = true});
    ASSERT_TRUE(sut.wait_for_matched(1, 20000ms)) << "the Cyclone reader never matched";

    for (int k = 0; k < kPerVehicle; ++k) {
        for (uint8_t id : {3, 4}) ASSERT_TRUE(sut.write(cpm_test::vehicle_state(id, 100 * k + id, 100 * k + id + 7, k)));
    }
    ASSERT_EQ(peer.wait(20000ms), 0) << "the Cyclone reader did not receive everything:\n" << peer.output();

    std::istringstream lines(peer.output());
    std::string ready;
    std::getline(lines, ready);
    std::multiset<std::string> expected, received;
    for (int k = 0; k < kPerVehicle; ++k) {
        for (int id : {3, 4}) {
            expected.insert(std::to_string(id) + " " + std::to_string(100 * k + id) + " " +
                            std::to_string(100 * k + id + 7) + " " + std::to_string(k));
        }
    }
    for (std::string line; std::getline(lines, line);) received.insert(line);
    EXPECT_EQ(received, expected);
}

TEST(CycloneInterop, HistoryServiceRecordsACyclonePublisher)
{
    auto options = cpm_test::isolated_options();
    options.shared_memory = false;  // the service is a new process on a port another may have used
    cpm::Participant participant(options);
    cpm_test::Process service({cpm_test::built_program("cpm_history"), "--window", "30s"});
    const std::string topic = cpm_test::unique_topic("cycloneState");
    constexpr int kCount = 20;
    // The Cyclone publisher waits for a reader: the service's, once it discovered the topic.
    cpm_test::Process peer({cpm_test::built_program("cyclone_peer"), "pub", std::to_string(kCount), "1", "2"}, peer_env(topic));
    ASSERT_EQ(peer.wait(30000ms), 0) << "the Cyclone publisher failed (no match or no acknowledgement)" << service.errors();

    cpm::HistoryClient client(participant);
    ASSERT_TRUE(cpm_test::wait_until([&] {
        auto r = client.latest(topic, "2");
        return !r.objects().empty() && r.objects()[0].samples_held() == kCount;
    }, 10000ms, 20ms)) << service.errors();
    // Sample k of vehicle id: create = 1000 k + id, pose.x = k; the key is the vehicle id.
    for (uint8_t id : {1, 2}) {
        auto at = client.at<VehicleState>(topic, id, 1000ull * 7 + id, cpm::HistoryBy::data);
        ASSERT_TRUE(at.ok()) << at.status << " " << at.error;
        EXPECT_EQ(at.sample.vehicle_id(), id);
        EXPECT_EQ(at.sample.pose().x(), 7);
        EXPECT_EQ(at.valid_after_ns, 1000ull * 7 + id + 60);
        EXPECT_DOUBLE_EQ(at.sample.speed(), 0.5 * id);
    }
    auto info = client.latest(topic, "1");
    ASSERT_FALSE(info.objects().empty());
    EXPECT_EQ(info.objects()[0].type_name(), "VehicleState");
    EXPECT_EQ(info.objects()[0].name(), topic + "/1");
}
