#include <cpm/AsyncReader.hpp>
#include <cpm/Error.hpp>
#include <cpm/MultiVehicleReader.hpp>
#include <cpm/Reader.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/Writer.hpp>
#include <cpm_test/Dds.hpp>
#include <cpm_test/Isolation.hpp>

#include <VehicleState.h>

#include <gtest/gtest.h>

#include <atomic>
#include <memory>
#include <mutex>
#include <thread>

using namespace std::chrono_literals;
using cpm_test::vehicle_state;

namespace {

class AsyncReaderTest : public ::testing::Test
{
protected:
    cpm::Participant writer_side{cpm_test::isolated_options()};
    cpm::Participant reader_side{cpm_test::isolated_options()};
    std::string topic = cpm_test::unique_topic("vehicleState");
    std::mutex mutex;
    std::vector<double> received;

    size_t count()
    {
        std::lock_guard<std::mutex> lock(mutex);
        return received.size();
    }
    std::function<void(std::vector<VehicleState>&)> recorder()
    {
        return [this](std::vector<VehicleState>& batch) {
            std::lock_guard<std::mutex> lock(mutex);
            for (auto& s : batch) received.push_back(s.pose().x());
        };
    }
};

}  // namespace

TEST_F(AsyncReaderTest, TransientLocalReceivesSamplesWrittenBeforeItExisted)
{
    cpm::Writer<VehicleState> writer(writer_side, topic,
                                     {.reliable = true, .keep_all = false, .history_depth = 10, .transient_local = true});
    for (int i = 0; i < 5; ++i) ASSERT_TRUE(writer.write(vehicle_state(1, i, i, i)));

    cpm::AsyncReader<VehicleState> sut(recorder(), reader_side, topic,
                                       {.reliable = true, .keep_all = false, .history_depth = 10, .transient_local = true});

    ASSERT_TRUE(cpm_test::wait_until([&] { return count() >= 5; }));
    std::lock_guard<std::mutex> lock(mutex);
    EXPECT_EQ(received, (std::vector<double>{0, 1, 2, 3, 4}));
}

TEST_F(AsyncReaderTest, CallbackRunsOnTheReadersOwnThreadNotTheCallers)
{
    std::atomic<std::thread::id> callback_thread{};
    cpm::AsyncReader<VehicleState> sut([&](std::vector<VehicleState>&) { callback_thread = std::this_thread::get_id(); },
                                       reader_side, topic, {.reliable = true});
    cpm::Writer<VehicleState> writer(writer_side, topic, {.reliable = true});
    ASSERT_TRUE(writer.wait_for_matched(1, 5000ms));
    ASSERT_TRUE(sut.wait_for_matched(1, 5000ms));  // both directions, or a write may be skipped

    ASSERT_TRUE(writer.write(vehicle_state(1, 1, 1)));

    ASSERT_TRUE(cpm_test::wait_until([&] { return callback_thread.load() != std::thread::id{}; }));
    EXPECT_NE(callback_thread.load(), std::this_thread::get_id());
}

TEST_F(AsyncReaderTest, ThrowingCallbackIsLoggedAndReadingGoesOn)
{
    std::atomic<int> calls{0};
    cpm::AsyncReader<VehicleState> sut(
        [&](std::vector<VehicleState>& batch) {
            calls += static_cast<int>(batch.size());
            throw std::runtime_error("callback failure on purpose");
        },
        reader_side, topic, {.reliable = true});
    cpm::Writer<VehicleState> writer(writer_side, topic, {.reliable = true});
    ASSERT_TRUE(writer.wait_for_matched(1, 5000ms));
    ASSERT_TRUE(sut.wait_for_matched(1, 5000ms));  // both directions, or a write may be skipped

    ASSERT_TRUE(writer.write(vehicle_state(1, 1, 1)));
    ASSERT_TRUE(cpm_test::wait_until([&] { return calls >= 1; }));
    ASSERT_TRUE(writer.write(vehicle_state(1, 2, 2)));

    EXPECT_TRUE(cpm_test::wait_until([&] { return calls >= 2; })) << "reader stopped after the exception";
}

TEST_F(AsyncReaderTest, DestroyedWhileItsCallbackRunsWaitsForItAndReturns)
{
    std::atomic<bool> in_callback{false}, callback_done{false};
    auto sut = std::make_unique<cpm::AsyncReader<VehicleState>>(
        [&](std::vector<VehicleState>&) {
            in_callback = true;
            std::this_thread::sleep_for(200ms);  // a slow user callback
            callback_done = true;
        },
        reader_side, topic, cpm::ReaderOptions{.reliable = true});
    cpm::Writer<VehicleState> writer(writer_side, topic, {.reliable = true});
    ASSERT_TRUE(writer.wait_for_matched(1, 5000ms));
    ASSERT_TRUE(sut->wait_for_matched(1, 5000ms));  // both directions, or a write may be skipped
    ASSERT_TRUE(writer.write(vehicle_state(1, 1, 1)));
    ASSERT_TRUE(cpm_test::wait_until([&] { return in_callback.load(); }));

    sut.reset();

    EXPECT_TRUE(callback_done) << "destructor returned while the callback still ran";
    EXPECT_TRUE(writer.write(vehicle_state(1, 2, 2)));  // nothing left to call back
}

TEST_F(AsyncReaderTest, StopBeforeAnyDataReturnsPromptlyAndNoCallbackFollows)
{
    std::atomic<int> calls{0};
    cpm::AsyncReader<VehicleState> sut([&](std::vector<VehicleState>&) { ++calls; }, reader_side, topic,
                                       {.reliable = true});
    cpm::Writer<VehicleState> writer(writer_side, topic, {.reliable = true});
    ASSERT_TRUE(writer.wait_for_matched(1, 5000ms));
    ASSERT_TRUE(sut.wait_for_matched(1, 5000ms));  // both directions, or a write may be skipped

    const auto start = std::chrono::steady_clock::now();
    sut.stop();
    const auto took = std::chrono::steady_clock::now() - start;
    ASSERT_TRUE(writer.write(vehicle_state(1, 1, 1)));
    ASSERT_TRUE(writer.wait_for_acknowledgments(5000ms));

    EXPECT_LT(took, 500ms) << "stop() waited for the worker's poll period";
    // The sample was delivered to the reader; a worker that still ran would call back soon after.
    EXPECT_TRUE(cpm_test::holds_for([&] { return calls == 0; }, 300ms)) << calls << " callbacks after stop()";
}

TEST_F(AsyncReaderTest, StopFromInsideTheCallbackEndsReading)
{
    std::atomic<int> calls{0};
    std::unique_ptr<cpm::AsyncReader<VehicleState>> sut;
    sut = std::make_unique<cpm::AsyncReader<VehicleState>>(
        [&](std::vector<VehicleState>&) {
            ++calls;
            sut->stop();
        },
        reader_side, topic, cpm::ReaderOptions{.reliable = true});
    cpm::Writer<VehicleState> writer(writer_side, topic, {.reliable = true});
    ASSERT_TRUE(writer.wait_for_matched(1, 5000ms));
    ASSERT_TRUE(sut->wait_for_matched(1, 5000ms));  // both directions, or a write may be skipped

    ASSERT_TRUE(writer.write(vehicle_state(1, 1, 1)));
    ASSERT_TRUE(cpm_test::wait_until([&] { return calls >= 1; }));
    ASSERT_TRUE(writer.write(vehicle_state(1, 2, 2)));
    ASSERT_TRUE(writer.wait_for_acknowledgments(5000ms));

    EXPECT_TRUE(cpm_test::holds_for([&] { return calls == 1; }, 300ms)) << calls << " callbacks";
    sut.reset();  // the destructor after a stop from inside must not hang or crash
}

// ---- options.dds_thread_callback: the callback on the DDS receive thread ----------------

namespace {
const cpm::ReaderOptions kOnDdsThread{.reliable = true, .keep_all = true, .dds_thread_callback = true};
}  // namespace

TEST_F(AsyncReaderTest, DdsThreadCallbackGetsEverySampleInOrder)
{
    // No claim on which thread: from a writer in the same process, Fast DDS delivers on the
    // writer's own thread, inside write() (ReaderOptions says so).
    cpm::AsyncReader<VehicleState> sut(recorder(), reader_side, topic, kOnDdsThread);
    cpm::Writer<VehicleState> writer(writer_side, topic, {.reliable = true, .keep_all = true});
    ASSERT_TRUE(writer.wait_for_matched(1, 5000ms));
    ASSERT_TRUE(sut.wait_for_matched(1, 5000ms));

    for (int i = 0; i < 200; ++i) ASSERT_TRUE(writer.write(vehicle_state(1, i, i, i)));

    ASSERT_TRUE(cpm_test::wait_until([&] { return count() >= 200; })) << count() << " of 200";
    std::vector<double> expected;
    for (int i = 0; i < 200; ++i) expected.push_back(i);
    std::lock_guard<std::mutex> lock(mutex);
    EXPECT_EQ(received, expected);
}

TEST_F(AsyncReaderTest, DdsThreadCallbackCanWriteAnswersFromInside)
{
    // The use it is made for: a pong that answers from the receive thread.
    const std::string answers = topic + "_answers";
    cpm::Writer<VehicleState> answer(reader_side, answers, {.reliable = true, .keep_all = true});
    cpm::AsyncReader<VehicleState> sut(
        [&](std::vector<VehicleState>& batch) {
            for (auto& s : batch) (void)answer.write(s);
        },
        reader_side, topic, kOnDdsThread);
    cpm::AsyncReader<VehicleState> answers_reader(recorder(), writer_side, answers, {.reliable = true, .keep_all = true});
    cpm::Writer<VehicleState> writer(writer_side, topic, {.reliable = true, .keep_all = true});
    ASSERT_TRUE(writer.wait_for_matched(1, 5000ms) && sut.wait_for_matched(1, 5000ms));
    ASSERT_TRUE(answer.wait_for_matched(1, 5000ms) && answers_reader.wait_for_matched(1, 5000ms));

    for (int i = 0; i < 20; ++i) ASSERT_TRUE(writer.write(vehicle_state(1, i, i, i)));

    EXPECT_TRUE(cpm_test::wait_until([&] { return count() >= 20; })) << count() << " of 20 answered";
}

TEST_F(AsyncReaderTest, DdsThreadCallbackThatThrowsIsLoggedAndReadingGoesOn)
{
    std::atomic<int> calls{0};
    cpm::AsyncReader<VehicleState> sut(
        [&](std::vector<VehicleState>& batch) {
            calls += static_cast<int>(batch.size());
            throw std::runtime_error("callback failure on purpose");
        },
        reader_side, topic, kOnDdsThread);
    cpm::Writer<VehicleState> writer(writer_side, topic, {.reliable = true, .keep_all = true});
    ASSERT_TRUE(writer.wait_for_matched(1, 5000ms) && sut.wait_for_matched(1, 5000ms));

    ASSERT_TRUE(writer.write(vehicle_state(1, 1, 1)));
    ASSERT_TRUE(cpm_test::wait_until([&] { return calls >= 1; }));
    ASSERT_TRUE(writer.write(vehicle_state(1, 2, 2)));

    EXPECT_TRUE(cpm_test::wait_until([&] { return calls == 2; })) << calls << " samples seen; a thrown batch must not come again";
}

TEST_F(AsyncReaderTest, DdsThreadCallbackStoppedFromInsideCallsBackNoMore)
{
    std::atomic<int> calls{0};
    std::unique_ptr<cpm::AsyncReader<VehicleState>> sut;
    sut = std::make_unique<cpm::AsyncReader<VehicleState>>(
        [&](std::vector<VehicleState>&) {
            ++calls;
            sut->stop();
        },
        reader_side, topic, kOnDdsThread);
    cpm::Writer<VehicleState> writer(writer_side, topic, {.reliable = true, .keep_all = true});
    ASSERT_TRUE(writer.wait_for_matched(1, 5000ms) && sut->wait_for_matched(1, 5000ms));

    ASSERT_TRUE(writer.write(vehicle_state(1, 1, 1)));
    ASSERT_TRUE(cpm_test::wait_until([&] { return calls >= 1; }));
    ASSERT_TRUE(writer.write(vehicle_state(1, 2, 2)));
    ASSERT_TRUE(writer.wait_for_acknowledgments(5000ms));

    EXPECT_TRUE(cpm_test::holds_for([&] { return calls == 1; }, 300ms)) << calls << " callbacks";
    sut.reset();
}

TEST_F(AsyncReaderTest, DdsThreadCallbackDestroyedWhileItRunsWaitsForIt)
{
    std::atomic<bool> in_callback{false}, callback_done{false};
    auto sut = std::make_unique<cpm::AsyncReader<VehicleState>>(
        [&](std::vector<VehicleState>&) {
            in_callback = true;
            std::this_thread::sleep_for(200ms);  // breaks the rule on purpose, to be caught running
            callback_done = true;
        },
        reader_side, topic, kOnDdsThread);
    cpm::Writer<VehicleState> writer(writer_side, topic, {.reliable = true});
    ASSERT_TRUE(writer.wait_for_matched(1, 5000ms) && sut->wait_for_matched(1, 5000ms));
    ASSERT_TRUE(writer.write(vehicle_state(1, 1, 1)));
    ASSERT_TRUE(cpm_test::wait_until([&] { return in_callback.load(); }));

    sut.reset();

    EXPECT_TRUE(callback_done) << "destructor returned while the callback still ran";
}

TEST_F(AsyncReaderTest, ReadersWithoutACallbackRefuseTheDdsThreadOptionNamingBoth)
{
    const cpm::ReaderOptions options{.dds_thread_callback = true};
    auto message_of = [](auto make) {
        try {
            make();
        } catch (const cpm::Error& e) {
            return std::string(e.what());
        }
        return std::string("(no error)");
    };
    const std::string reader = message_of([&] { cpm::Reader<VehicleState> r(reader_side, topic, options); });
    EXPECT_NE(reader.find("dds_thread_callback"), std::string::npos) << reader;
    EXPECT_NE(reader.find("Reader on topic '" + topic + "'"), std::string::npos) << reader;
    const std::string abstract = message_of([&] { cpm::ReaderAbstract<VehicleState> r(reader_side, topic, options); });
    EXPECT_NE(abstract.find("dds_thread_callback"), std::string::npos) << abstract;
    EXPECT_NE(abstract.find("ReaderAbstract"), std::string::npos) << abstract;
    const std::string multi =
        message_of([&] { cpm::MultiVehicleReader<VehicleState> r(reader_side, topic, std::vector<uint8_t>{1}, options); });
    EXPECT_NE(multi.find("dds_thread_callback"), std::string::npos) << multi;
    EXPECT_NE(multi.find("MultiVehicleReader"), std::string::npos) << multi;
}
