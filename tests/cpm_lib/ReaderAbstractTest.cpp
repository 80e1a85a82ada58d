#include <cpm/ReaderAbstract.hpp>
#include <cpm/Writer.hpp>
#include <cpm_test/Dds.hpp>
#include <cpm_test/Isolation.hpp>

#include <VehicleState.h>

#include <gtest/gtest.h>

using namespace std::chrono_literals;
using cpm_test::vehicle_state;

TEST(ReaderAbstract, ReliableKeepAllReceivesEverySampleInOrder)
{
    cpm::Participant writer_side(cpm_test::isolated_options());
    cpm::Participant reader_side(cpm_test::isolated_options());
    const std::string topic = cpm_test::unique_topic("vehicleState");
    cpm::Writer<VehicleState> writer(writer_side, topic, {.reliable = true, .keep_all = true});
    cpm::ReaderAbstract<VehicleState> sut(reader_side, topic, {.reliable = true, .keep_all = true});
    ASSERT_TRUE(writer.wait_for_matched(1, 5000ms));
    ASSERT_TRUE(sut.wait_for_matched(1, 5000ms));
    constexpr int kSamples = 5000;

    for (int i = 0; i < kSamples; ++i) ASSERT_TRUE(writer.write(vehicle_state(1, i, i, i)));
    std::vector<VehicleState> received;
    cpm_test::wait_until([&] {
        for (auto& s : sut.take()) received.push_back(s);
        return received.size() >= kSamples;
    }, 10000ms);

    ASSERT_EQ(received.size(), size_t(kSamples));
    for (int i = 0; i < kSamples; ++i) ASSERT_EQ(received[i].pose().x(), i) << "at " << i;
}

TEST(ReaderAbstract, WaitForDataTimesOutWithNothingAndWakesOnData)
{
    cpm::Participant participant(cpm_test::isolated_options());
    const std::string topic = cpm_test::unique_topic("vehicleState");
    cpm::ReaderAbstract<VehicleState> sut(participant, topic, {.reliable = true});

    EXPECT_FALSE(sut.wait_for_data(50ms));
    EXPECT_TRUE(sut.take().empty());

    cpm::Writer<VehicleState> writer(participant, topic, {.reliable = true});
    ASSERT_TRUE(writer.wait_for_matched(1, 5000ms));
    ASSERT_TRUE(sut.wait_for_matched(1, 5000ms));  // both directions, or a write may be skipped
    ASSERT_TRUE(writer.write(vehicle_state(2, 1, 1, 5)));
    ASSERT_TRUE(sut.wait_for_data(5000ms));
    auto samples = sut.take();

    ASSERT_EQ(samples.size(), 1u);
    EXPECT_EQ(samples[0].vehicle_id(), 2);
    EXPECT_TRUE(sut.take().empty()) << "take() returns each sample once";
}
