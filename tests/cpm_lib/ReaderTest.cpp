// Reader<T> over real DDS (one process, two participants on this test's own domain).
#include <cpm/Error.hpp>
#include <cpm/Reader.hpp>
#include <cpm/Writer.hpp>
#include <cpm_test/Dds.hpp>
#include <cpm_test/Isolation.hpp>

#include <VehicleObservation.h>
#include <VehicleState.h>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <atomic>
#include <thread>

using namespace std::chrono_literals;
using cpm_test::vehicle_state;
using ::testing::HasSubstr;

namespace {

using cpm_test::kMs;
using cpm_test::kT0;
using cpm_test::kReliable;
using cpm_test::kReliableReader;

class ReaderTest : public ::testing::Test
{
protected:
    cpm::Participant writer_side{cpm_test::isolated_options()};
    cpm::Participant reader_side{cpm_test::isolated_options()};
    std::string topic = cpm_test::unique_topic("vehicleState");

    template <class W, class R>
    void connect(W& writer, R& reader)
    {
        ASSERT_TRUE(writer.wait_for_matched(1, 5000ms)) << "writer never matched";
        ASSERT_TRUE(reader.wait_for_matched(1, 5000ms)) << "reader never matched";
    }
    template <class W>
    void delivered(W& writer)
    {
        ASSERT_TRUE(writer.wait_for_acknowledgments(5000ms)) << "samples were not acknowledged";
    }
};

}  // namespace

TEST_F(ReaderTest, CpmLabScenarioReturnsIndex4WithAge900ms)
{
    cpm::Writer<VehicleState> writer(writer_side, topic, kReliable);
    cpm::Reader<VehicleState> sut(reader_side, topic, kReliableReader);
    connect(writer, sut);

    for (int i = 0; i <= 10; ++i) {
        ASSERT_TRUE(writer.write(vehicle_state(1, kT0 + i * 1000 * kMs, kT0 + i * 1000 * kMs + 400 * kMs, i)));
    }
    delivered(writer);
    auto result = sut.get_sample(kT0 + 5300 * kMs);

    ASSERT_TRUE(result.valid);
    EXPECT_EQ(result.sample.pose().x(), 4);
    EXPECT_EQ(result.age_ns, 900 * kMs);
}

TEST_F(ReaderTest, GetSampleReturnsNewestValidEvenWhenArrivalsAreOutOfOrder)
{
    cpm::Writer<VehicleState> writer(writer_side, topic, kReliable);
    cpm::Reader<VehicleState> sut(reader_side, topic, kReliableReader);
    connect(writer, sut);

    for (int i : {3, 0, 4, 1, 2}) ASSERT_TRUE(writer.write(vehicle_state(1, kT0 + i * kMs, kT0 + i * kMs, i)));
    delivered(writer);

    auto at_2 = sut.get_sample(kT0 + 2 * kMs);
    auto at_4 = sut.get_sample(kT0 + 4 * kMs);

    ASSERT_TRUE(at_2.valid);
    EXPECT_EQ(at_2.sample.pose().x(), 2);
    ASSERT_TRUE(at_4.valid);
    EXPECT_EQ(at_4.sample.pose().x(), 4);
}

TEST_F(ReaderTest, EqualCreateStampGoesToTheLaterArrival)
{
    cpm::Writer<VehicleState> writer(writer_side, topic, kReliable);
    cpm::Reader<VehicleState> sut(reader_side, topic, kReliableReader);
    connect(writer, sut);

    ASSERT_TRUE(writer.write(vehicle_state(1, kT0, kT0, 1)));
    ASSERT_TRUE(writer.write(vehicle_state(1, kT0, kT0, 2)));
    delivered(writer);

    auto result = sut.get_sample(kT0 + kMs);
    ASSERT_TRUE(result.valid);
    EXPECT_EQ(result.sample.pose().x(), 2);
}

TEST_F(ReaderTest, SampleValidInTheFutureIsNotReturnedUntilThen)
{
    cpm::Writer<VehicleState> writer(writer_side, topic, kReliable);
    cpm::Reader<VehicleState> sut(reader_side, topic, kReliableReader);
    connect(writer, sut);

    ASSERT_TRUE(writer.write(vehicle_state(1, kT0, kT0 + 60 * kMs, 7)));
    delivered(writer);

    auto before = sut.get_sample(kT0 + 59 * kMs);
    auto after = sut.get_sample(kT0 + 61 * kMs);

    EXPECT_FALSE(before.valid);
    ASSERT_TRUE(after.valid);
    EXPECT_EQ(after.sample.pose().x(), 7);
    EXPECT_EQ(after.age_ns, 1 * kMs);
}

TEST_F(ReaderTest, CpmLabFormSetsAgeToMaxWhenNothingIsValid)
{
    cpm::Reader<VehicleState> sut(reader_side, topic);
    VehicleState sample;
    uint64_t age = 0;

    sut.get_sample(kT0, sample, age);

    EXPECT_EQ(age, UINT64_MAX);
}

TEST_F(ReaderTest, BufferBoundDropsTheEarliestArrivalsAndCountsThem)
{
    cpm::Writer<VehicleState> writer(writer_side, topic, kReliable);
    cpm::ReaderOptions options = kReliableReader;
    options.buffer_capacity = 5;
    cpm::Reader<VehicleState> sut(reader_side, topic, options);
    connect(writer, sut);

    for (int i = 0; i < 12; ++i) ASSERT_TRUE(writer.write(vehicle_state(1, kT0 + i, kT0 + i, i)));
    delivered(writer);

    EXPECT_EQ(sut.overflow_count(), 7u);
    auto oldest_kept = sut.get_sample(kT0 + 7);  // 0..6 were dropped
    ASSERT_TRUE(oldest_kept.valid);
    EXPECT_EQ(oldest_kept.sample.pose().x(), 7);
}

TEST_F(ReaderTest, VehicleIdFilterIgnoresOtherVehicles)
{
    cpm::Writer<VehicleState> writer(writer_side, topic, kReliable);
    cpm::ReaderOptions options = kReliableReader;
    options.vehicle_id = 3;
    cpm::Reader<VehicleState> sut(reader_side, topic, options);
    connect(writer, sut);

    ASSERT_TRUE(writer.write(vehicle_state(3, kT0, kT0, 30)));
    ASSERT_TRUE(writer.write(vehicle_state(4, kT0 + 1, kT0 + 1, 40)));
    delivered(writer);

    auto result = sut.get_sample(kT0 + kMs);
    ASSERT_TRUE(result.valid);
    EXPECT_EQ(result.sample.vehicle_id(), 3);
    EXPECT_EQ(result.sample.pose().x(), 30);
}

TEST_F(ReaderTest, ConcurrentGetSampleWhileSamplesArriveNeverGoesBackwards)
{
    cpm::Writer<VehicleState> writer(writer_side, topic, kReliable);
    cpm::Reader<VehicleState> sut(reader_side, topic, kReliableReader);
    connect(writer, sut);
    constexpr int kSamples = 2000;

    std::thread producer([&] {
        for (int i = 1; i <= kSamples; ++i) (void)writer.write(vehicle_state(1, kT0 + i, kT0 + i, i));
    });
    double last = 0;
    bool went_back = false;
    const bool saw_last = cpm_test::wait_until([&] {
        auto result = sut.get_sample(kT0 + kSamples);
        if (result.valid) {
            went_back = went_back || result.sample.pose().x() < last;
            last = result.sample.pose().x();
        }
        return last == kSamples;
    }, 10000ms, 0ms);
    producer.join();

    EXPECT_FALSE(went_back);
    EXPECT_TRUE(saw_last) << "last sample seen: " << last;
}

TEST_F(ReaderTest, EmptyTopicNameIsAnError)
{
    try {
        cpm::Reader<VehicleState> sut(reader_side, "");
        FAIL() << "no error";
    } catch (const cpm::Error& e) {
        EXPECT_THAT(e.what(), HasSubstr("topic name is empty"));
    }
}

TEST_F(ReaderTest, TopicWithAnotherTypeIsAnErrorNamingBothTypes)
{
    cpm::Writer<VehicleState> existing(reader_side, topic);
    try {
        cpm::Reader<VehicleObservation> sut(reader_side, topic);
        FAIL() << "no error";
    } catch (const cpm::Error& e) {
        EXPECT_THAT(e.what(), HasSubstr(topic));
        EXPECT_THAT(e.what(), HasSubstr("VehicleState"));
        EXPECT_THAT(e.what(), HasSubstr("VehicleObservation"));
    }
}

TEST_F(ReaderTest, WaitForNewSampleWakesOnEachArrivalOfItsVehicleOnly)
{
    cpm::Writer<VehicleState> writer(writer_side, topic, kReliable);
    cpm::ReaderOptions mine = kReliableReader;
    mine.vehicle_id = 3;
    cpm::Reader<VehicleState> sut(reader_side, topic, mine);
    connect(writer, sut);
    EXPECT_FALSE(sut.wait_for_new_sample(50ms)) << "nothing has arrived";

    ASSERT_TRUE(writer.write(vehicle_state(4, kT0, kT0, 1)));
    delivered(writer);
    EXPECT_FALSE(sut.wait_for_new_sample(100ms)) << "another vehicle's sample does not wake it";

    std::atomic<bool> woke{false};
    std::thread waiter([&] { woke = sut.wait_for_new_sample(5s); });
    std::this_thread::sleep_for(20ms);
    ASSERT_TRUE(writer.write(vehicle_state(3, kT0, kT0, 2)));
    waiter.join();
    EXPECT_TRUE(woke) << "its own vehicle's sample does";
    EXPECT_TRUE(sut.get_sample(kT0 + kMs).valid);
    EXPECT_FALSE(sut.wait_for_new_sample(50ms)) << "each arrival wakes one wait";
}
