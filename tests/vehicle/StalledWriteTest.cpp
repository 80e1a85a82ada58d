// A car's microcontroller is a chip of its own: nothing on the lab's network can stop its clock,
// its answers or its watchdog. The simulators that play it (firmware_sim's model, firmware_hil's
// AVR in simavr) also publish the car's true pose over DDS, and a DDS write can stall for
// seconds: Fast DDS 2.9 waits a second per send, again and again, on the shared-memory port of a
// reader whose process was killed while it held that port's lock (seen once in CI, where the
// AVR car under firmware_hil never braked after its bridge was killed). These tests stall the
// write on purpose - a reader in this process whose callback runs inside the writer's write()
// and sleeps - and read the car's serial line meanwhile, as its bridge would.
#include <cpm/vehicle/FirmwareHil.hpp>
#include <cpm/vehicle/FirmwareSimNode.hpp>
#include <cpm/vehicle/Protocol.hpp>
#include <cpm/vehicle/SerialPort.hpp>

#include <cpm/AsyncReader.hpp>
#include <cpm/Logging.hpp>
#include <cpm/Participant.hpp>
#include <cpm/Writer.hpp>
#include <cpm_test/Isolation.hpp>

#include <VehicleObservation.h>

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <functional>
#include <thread>
#include <variant>

using namespace std::chrono_literals;

namespace {

/// Holds up the next write of a true pose, inside that write, for `how_long`, once armed.
class WriteStaller
{
public:
    explicit WriteStaller(std::chrono::milliseconds how_long)
        : reader_(
              [this, how_long](std::vector<VehicleObservation>&) {
                  if (!armed_.exchange(false)) return;
                  stalling_ = true;
                  std::this_thread::sleep_for(how_long);
                  stalling_ = false;
              },
              "vehicleObservation", {.dds_thread_callback = true})
    {
    }
    void arm() { armed_ = true; }
    bool stalling() const { return stalling_; }

private:
    std::atomic<bool> armed_{false}, stalling_{false};
    cpm::AsyncReader<VehicleObservation> reader_;
};

/// Counts the state packets that come over the car's line for `how_long`.
int state_packets_within(cpm::vehicle::SerialPort& line, std::chrono::milliseconds how_long,
                         cpm::vehicle::DecoderErrors* errors = nullptr)
{
    cpm::vehicle::FrameDecoder decoder;
    int states = 0;
    const auto end = std::chrono::steady_clock::now() + how_long;
    uint8_t bytes[512];
    while (std::chrono::steady_clock::now() < end) {
        const long n = line.read_some(bytes, sizeof bytes, 5);
        if (n < 0) break;
        decoder.feed(bytes, size_t(n), [&](const cpm::vehicle::Packet& p) {
            states += std::holds_alternative<cpm::vehicle::StatePacket>(p);
        });
    }
    if (errors) *errors = decoder.errors();
    return states;
}

/// Runs a node's loop on a thread of its own until destroyed.
class Running
{
public:
    explicit Running(std::function<void(const std::function<bool()>&)> run)
        : thread_([this, run = std::move(run)] { run([this] { return stop_.load(); }); })
    {
    }
    ~Running()
    {
        stop_ = true;
        thread_.join();
    }

private:
    std::atomic<bool> stop_{false};
    std::thread thread_;
};

/// The staller itself, before any node writes: a write in this process must really wait for it
/// (Fast DDS hands a sample to a reader of the same process inside write(); were that ever off,
/// the tests would pass without stalling anything).
void expect_a_write_held_up(WriteStaller& staller)
{
    cpm::Writer<VehicleObservation> writer("vehicleObservation");
    ASSERT_TRUE(writer.wait_for_matched(1, 5000ms));
    staller.arm();
    const auto before = std::chrono::steady_clock::now();
    (void)writer.write(VehicleObservation{});
    EXPECT_GE(std::chrono::steady_clock::now() - before, 1400ms) << "the staller did not hold up a write in this process";
}

/// The line keeps talking at its 50 Hz while a true pose's write is held up for 1.5 s.
void expect_state_packets_through_a_stalled_write(const std::string& device, WriteStaller& staller,
                                                  const std::function<std::string()>& stats)
{
    cpm::vehicle::SerialPort line(device, 115200);
    ASSERT_GT(state_packets_within(line, 500ms), 15) << "the car did not start talking on " << device;
    staller.arm();
    const auto deadline = std::chrono::steady_clock::now() + 2s;
    while (!staller.stalling() && std::chrono::steady_clock::now() < deadline) std::this_thread::sleep_for(1ms);
    ASSERT_TRUE(staller.stalling()) << "no true pose was written within 2 s";
    cpm::vehicle::DecoderErrors errors;
    const int during = state_packets_within(line, 1000ms, &errors);
    EXPECT_TRUE(staller.stalling()) << "the write was held up for less than the second counted";
    EXPECT_GE(during, 30) << "state packets in the second a write of the true pose stalled (50 due); frames thrown away: "
                          << errors.total() << "; the node's statistics: " << stats();
}

}  // namespace

class StalledWrite : public ::testing::Test
{
protected:
    void SetUp() override { (void)cpm_test::test_domain_id(); }  // the nodes' default participant joins it
};

TEST_F(StalledWrite, TheAvrChipKeepsItsClockAndItsLineWhileItsTruePoseCannotBeWritten)
{
    WriteStaller staller(1500ms);
    expect_a_write_held_up(staller);
    cpm::vehicle::FirmwareHilOptions options;
    options.elf = CPM_FIRMWARE_ELF;
    options.car.vehicle_id = 7;
    cpm::vehicle::FirmwareHilNode node(options);
    Running running([&](const std::function<bool()>& stop) { node.run(stop); });
    expect_state_packets_through_a_stalled_write(node.device(), staller, [&] { return node.stats_json(); });
}

TEST_F(StalledWrite, TheModelCarKeepsItsClockAndItsLineWhileItsTruePoseCannotBeWritten)
{
    WriteStaller staller(1500ms);
    expect_a_write_held_up(staller);
    cpm::vehicle::FirmwareSimNodeOptions options;
    options.cars.push_back({.vehicle_id = 7});
    cpm::vehicle::FirmwareSimNode node(options);
    Running running([&](const std::function<bool()>& stop) { node.run(stop); });
    expect_state_packets_through_a_stalled_write(node.devices().at(0).second, staller, [&] { return node.stats_json(); });
}

// The loops' first message would create the log's DDS entities, and creating one waits for a
// write stalled inside a reader of the process: the nodes connect the log before they start.
TEST_F(StalledWrite, AMessageLoggedWhileAWriteStallsWaitsForNothingOnceTheLogIsConnected)
{
    WriteStaller staller(1500ms);
    cpm::Logging::instance().connect();
    cpm::Writer<VehicleObservation> writer("vehicleObservation");
    ASSERT_TRUE(writer.wait_for_matched(1, 5000ms));
    staller.arm();
    std::thread stalled([&] { (void)writer.write(VehicleObservation{}); });
    while (!staller.stalling()) std::this_thread::sleep_for(1ms);
    const auto before = std::chrono::steady_clock::now();
    CPM_LOG_WARN("a message while a write stalls");
    const auto took = std::chrono::steady_clock::now() - before;
    EXPECT_TRUE(staller.stalling()) << "the write was held up for less than the message took";
    EXPECT_LT(took, 500ms) << "logging waited for the stalled write";
    stalled.join();
}
