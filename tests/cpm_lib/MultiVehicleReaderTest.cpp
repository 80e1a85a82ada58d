#include <cpm/Error.hpp>
#include <cpm/MultiVehicleReader.hpp>
#include <cpm/Writer.hpp>
#include <cpm_test/Dds.hpp>
#include <cpm_test/Isolation.hpp>

#include <VehicleState.h>

#include <gtest/gtest.h>

using namespace std::chrono_literals;
using cpm_test::vehicle_state;

namespace {

using cpm_test::kMs;
using cpm_test::kT0;
using cpm_test::kReliable;
using cpm_test::kReliableReader;
}  // namespace

TEST(MultiVehicleReader, ReadsConfiguredVehiclesWithAgesAndIgnoresOthers)
{
    cpm::Participant writer_side(cpm_test::isolated_options());
    cpm::Participant reader_side(cpm_test::isolated_options());
    const std::string topic = cpm_test::unique_topic("vehicleState");
    cpm::Writer<VehicleState> writer(writer_side, topic, kReliable);
    cpm::MultiVehicleReader<VehicleState> sut(reader_side, topic, std::vector<uint8_t>{1, 3, 7}, kReliableReader);
    ASSERT_TRUE(writer.wait_for_matched(1, 5000ms));
    ASSERT_TRUE(sut.wait_for_matched(1, 5000ms));

    for (uint8_t id : {1, 2, 3, 7}) {
        for (int k = 0; k < 3; ++k) {
            const uint64_t create = kT0 + k * 100 * kMs + id * kMs;
            ASSERT_TRUE(writer.write(vehicle_state(id, create, create + 60 * kMs, id * 10 + k)));
        }
    }
    ASSERT_TRUE(writer.wait_for_acknowledgments(5000ms));
    const uint64_t t_now = kT0 + 300 * kMs;
    auto results = sut.get_samples(t_now);

    ASSERT_EQ(results.size(), 3u);
    EXPECT_EQ(results.count(2), 0u) << "vehicle 2 was not asked for";
    for (uint8_t id : {1, 3, 7}) {
        ASSERT_TRUE(results.count(id)) << "vehicle " << int(id);
        const auto& r = results.at(id);
        ASSERT_TRUE(r.valid) << "vehicle " << int(id);
        EXPECT_EQ(r.sample.vehicle_id(), id);
        EXPECT_EQ(r.sample.pose().x(), id * 10 + 2);
        EXPECT_EQ(r.age_ns, t_now - (kT0 + 200 * kMs + id * kMs + 60 * kMs));
    }
}

TEST(MultiVehicleReader, VehicleWithoutSamplesIsInvalidInBothForms)
{
    cpm::Participant participant(cpm_test::isolated_options());
    cpm::MultiVehicleReader<VehicleState> sut(participant, cpm_test::unique_topic("vehicleState"),
                                              std::vector<uint8_t>{4});
    std::map<uint8_t, VehicleState> samples;
    std::map<uint8_t, uint64_t> ages;

    auto results = sut.get_samples(kT0);
    sut.get_samples(kT0, samples, ages);

    EXPECT_FALSE(results.at(4).valid);
    EXPECT_EQ(ages.at(4), UINT64_MAX);
}

TEST(MultiVehicleReader, CountConstructorReadsIdsOneToNInclusive)
{
    cpm::ParticipantOptions options = cpm_test::isolated_options();
    const std::string topic = cpm_test::unique_topic("vehicleState");
    // The count constructor uses the default participant; isolated_options() pointed
    // CPM_DOMAIN_ID at this process's domain.
    cpm::MultiVehicleReader<VehicleState> sut(topic, 12, kReliableReader);
    cpm::Participant writer_side(options);
    cpm::Writer<VehicleState> writer(writer_side, topic, kReliable);
    ASSERT_TRUE(writer.wait_for_matched(1, 5000ms));
    ASSERT_TRUE(sut.wait_for_matched(1, 5000ms));  // both directions, or a write may be skipped

    for (int id = 0; id <= 13; ++id) ASSERT_TRUE(writer.write(vehicle_state(uint8_t(id), kT0, kT0, id)));
    ASSERT_TRUE(writer.wait_for_acknowledgments(5000ms));
    auto results = sut.get_samples(kT0);

    ASSERT_EQ(results.size(), 12u);
    EXPECT_EQ(results.begin()->first, 1);
    EXPECT_EQ(results.rbegin()->first, 12);
    for (auto& [id, r] : results) EXPECT_TRUE(r.valid) << "vehicle " << int(id) << " missing (instance limit?)";
}

TEST(MultiVehicleReader, ZeroVehiclesIsAnError)
{
    cpm::Participant participant(cpm_test::isolated_options());
    EXPECT_THROW(cpm::MultiVehicleReader<VehicleState>(participant, "vehicleState", std::vector<uint8_t>{}),
                 cpm::Error);
    EXPECT_THROW(cpm::MultiVehicleReader<VehicleState>("vehicleState", 0), cpm::Error);
}
