// A car's microcontroller is a chip of its own: nothing on the lab's network can stop its clock,
// its answers or its watchdog, and the bridge answers each of its state packets. The simulators
// that play the chip (firmware_sim's model, firmware_hil's AVR in simavr) publish the car's true
// pose over DDS, the bridge its state, and a DDS write can stall for seconds: Fast DDS 2.9 waits
// a second per send, again and again, on the shared-memory port of a reader whose process was
// killed while it held that port's lock (seen once in CI, where the AVR car under firmware_hil
// never braked after its bridge was killed). These tests stall the write on purpose - a reader
// in this process whose callback runs inside the writer's write() and sleeps - and work the
// car's serial line meanwhile, as its bridge or its chip would.
#include <cpm/vehicle/BridgeNode.hpp>
#include <cpm/vehicle/FirmwareHil.hpp>
#include <cpm/vehicle/FirmwareSimNode.hpp>
#include <cpm/vehicle/Protocol.hpp>
#include <cpm/vehicle/SerialPort.hpp>

#include <cpm/AsyncReader.hpp>
#include <cpm/Logging.hpp>
#include <cpm/Participant.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/Writer.hpp>
#include <cpm_test/Dds.hpp>
#include <cpm_test/Isolation.hpp>
#include <cpm_test/Process.hpp>
#include <cpm_test/TempDir.hpp>

#include "WriterThread.hpp"

#include <VehicleObservation.h>
#include <VehicleState.h>

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <functional>
#include <thread>
#include <variant>

using namespace std::chrono_literals;

namespace {

/// Holds up the next write of a T on `topic`, inside that write, for `how_long`, once armed.
template <class T>
class WriteStaller
{
public:
    WriteStaller(const std::string& topic, std::chrono::milliseconds how_long)
        : topic_(topic), reader_(
              [this, how_long](std::vector<T>&) {
                  if (!armed_.exchange(false)) return;
                  stalling_ = true;
                  std::this_thread::sleep_for(how_long);
                  stalling_ = false;
              },
              topic, {.dds_thread_callback = true})
    {
    }
    void arm() { armed_ = true; }
    bool stalling() const { return stalling_; }
    const std::string& topic() const { return topic_; }

private:
    const std::string topic_;
    std::atomic<bool> armed_{false}, stalling_{false};
    cpm::AsyncReader<T> reader_;
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

/// Plays the car's microcontroller on a pty for `how_long`: a state packet every 20 ms, as the
/// firmware sends them; counts the bridge's commands that come back.
int commands_within(cpm::vehicle::PseudoTerminal& line, std::chrono::milliseconds how_long, uint32_t& tick)
{
    cpm::vehicle::FrameDecoder decoder;
    int commands = 0;
    const auto start = std::chrono::steady_clock::now();
    auto next = start;
    uint8_t bytes[512];
    while (std::chrono::steady_clock::now() < start + how_long) {
        cpm::vehicle::StatePacket state;
        state.tick = tick += 20;
        state.vehicle_id = 7;
        state.battery_mv = 7400;
        const auto frame = cpm::vehicle::encode_frame(state);
        (void)line.write_frame(frame.data(), frame.size());
        next += 20ms;
        while (std::chrono::steady_clock::now() < next) {
            const long n = line.read_available(bytes, sizeof bytes);
            if (n > 0) {
                decoder.feed(bytes, size_t(n), [&](const cpm::vehicle::Packet& p) {
                    commands += std::holds_alternative<cpm::vehicle::CommandPacket>(p);
                });
            }
            std::this_thread::sleep_for(1ms);
        }
    }
    return commands;
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
template <class T>
void expect_a_write_held_up(WriteStaller<T>& staller)
{
    cpm::Writer<T> writer(staller.topic());
    ASSERT_TRUE(writer.wait_for_matched(1, 5000ms));
    staller.arm();
    const auto before = std::chrono::steady_clock::now();
    (void)writer.write(T{});
    EXPECT_GE(std::chrono::steady_clock::now() - before, 1400ms) << "the staller did not hold up a write in this process";
}

/// The line keeps talking at its 50 Hz while a true pose's write is held up for 1.5 s.
void expect_state_packets_through_a_stalled_write(const std::string& device, WriteStaller<VehicleObservation>& staller,
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
    WriteStaller<VehicleObservation> staller("vehicleObservation", 1500ms);
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
    WriteStaller<VehicleObservation> staller("vehicleObservation", 1500ms);
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
    WriteStaller<VehicleObservation> staller("vehicleObservation", 1500ms);
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

// The bridge answers each state packet with a command, then publishes the car's state: a state
// that cannot be written must not hold up the next command (the firmware's watchdog would brake
// the car after 250 ms).
TEST_F(StalledWrite, TheBridgeKeepsAnsweringItsCarWhileItsStateCannotBeWritten)
{
    WriteStaller<VehicleState> staller("vehicleState", 1500ms);
    expect_a_write_held_up(staller);
    cpm::vehicle::PseudoTerminal line;
    cpm::vehicle::BridgeNode bridge(cpm::vehicle::BridgeNodeOptions{.vehicle_id = 7, .device = line.device_path()});
    Running running([&](const std::function<bool()>& stop) { bridge.run(stop); });
    uint32_t tick = 0;
    ASSERT_GT(commands_within(line, 1000ms, tick), 30) << "the bridge did not answer on " << line.device_path();
    staller.arm();
    const auto deadline = std::chrono::steady_clock::now() + 2s;
    while (!staller.stalling() && std::chrono::steady_clock::now() < deadline) (void)commands_within(line, 20ms, tick);
    ASSERT_TRUE(staller.stalling()) << "no state was written within 2 s";
    const int during = commands_within(line, 1000ms, tick);
    EXPECT_TRUE(staller.stalling()) << "the write was held up for less than the second counted";
    EXPECT_GE(during, 30) << "commands in the second a write of the car's state stalled (50 due); the bridge's statistics: "
                          << bridge.stats().to_json();
}

// While a write is held up, a loop's samples wait up to the thread's capacity; older ones are
// dropped, and once the writes go through again a warning says how many and for how long.
TEST_F(StalledWrite, WhatAStalledWriteMadeTheWriterThreadDropIsCountedInAWarning)
{
    cpm_test::TempDir dir;
    const std::string log_file = dir.file("log.csv");
    cpm::Logging::instance().set_file(log_file);
    WriteStaller<VehicleState> staller("vehicleState", 1000ms);
    cpm::ReaderAbstract<VehicleState> reader(cpm::Participant::default_participant(), "vehicleState", cpm_test::kReliableReader);
    cpm::Writer<VehicleState> writer(cpm::Participant::default_participant(), "vehicleState", cpm_test::kReliable);
    ASSERT_TRUE(writer.wait_for_matched(2, 5000ms));
    {
        cpm::vehicle::WriterThread<VehicleState> thread(writer, "vehicleState", 4, true);
        staller.arm();
        thread.write(cpm_test::vehicle_state(7, 1, 1, 0));
        while (!staller.stalling()) std::this_thread::sleep_for(1ms);
        for (int i = 1; i < 10; ++i) thread.write(cpm_test::vehicle_state(7, 1 + i, 1 + i, i));
        std::vector<double> tags;
        ASSERT_TRUE(cpm_test::wait_until([&] {
            for (const auto& s : reader.take()) tags.push_back(s.pose().x());
            return tags.size() >= 5;
        }, 5s)) << tags.size() << " samples arrived";
        // The one held up, then the newest four; the five between were dropped.
        EXPECT_EQ(tags, (std::vector<double>{0, 6, 7, 8, 9}));
    }
    cpm::Logging::instance().set_file("");
    const std::string log = cpm_test::file_text(log_file);
    EXPECT_NE(log.find("'vehicleState': 5 samples were not published: a DDS write was held up for 1."), std::string::npos) << log;
}
