// Publishes the VehicleState of a few simulated vehicles driving circles, at 50 Hz, each
// sample valid 60 ms after its creation (as a real vehicle's measurement delay would be).
//
//   vehicle_state_writer [--vehicles N] [--seconds S] [--dds_domain D]
#include <cpm/CommandLine.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/init.hpp>
#include <cpm/stamp_message.hpp>

#include <VehicleState.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>
#include <thread>

namespace {

constexpr uint64_t kPeriodNs = 20'000'000;        // 50 Hz
constexpr uint64_t kExpectedDelayNs = 60'000'000;  // valid_after = create + 60 ms

const char* kHelp =
    "usage: vehicle_state_writer [--vehicles N (1..20, default 4)] [--seconds S (default 5)] [--dds_domain D]\n"
    "Publishes simulated vehicles' VehicleState on topic 'vehicleState' at 50 Hz.\n";

int run(int argc, char** argv)
{
    const auto flags = cpm::cli::parse_flags(argc, argv, {{"--vehicles", true}, {"--seconds", true}}, "vehicle_state_writer");
    const int vehicles = int(cpm::cli::parse_integer("--vehicles", flags.get("--vehicles", "4"), 1, 20));
    const int seconds = int(cpm::cli::parse_integer("--seconds", flags.get("--seconds", "5"), 1, 3600));
    cpm::init(argc, argv);

    cpm::Writer<VehicleState> writer("vehicleState");
    const uint64_t start = cpm::get_time_ns();
    uint64_t next = start;
    uint64_t written = 0;
    while (next < start + uint64_t(seconds) * 1'000'000'000ull) {
        const double t = double(next - start) * 1e-9;
        for (int id = 1; id <= vehicles; ++id) {
            // Vehicle id drives a circle of radius 0.5 + 0.25 id at 0.5 m/s.
            const double radius = 0.5 + 0.25 * id, speed = 0.5, angle = speed * t / radius;
            VehicleState state;
            state.vehicle_id(static_cast<uint8_t>(id));
            state.pose().x(radius * std::cos(angle));
            state.pose().y(radius * std::sin(angle));
            state.pose().yaw(angle + M_PI / 2);
            state.speed(speed);
            state.odometer_distance(speed * t);
            state.battery_voltage(8.2 - 0.01 * t);
            cpm::stamp_message(state, cpm::get_time_ns(), kExpectedDelayNs);
            if (writer.write(state)) ++written;
        }
        next += kPeriodNs;
        std::this_thread::sleep_until(std::chrono::system_clock::time_point(std::chrono::nanoseconds(next)));
    }
    std::printf("writer: published %llu VehicleState samples for %d vehicles in %d s\n",
                static_cast<unsigned long long>(written), vehicles, seconds);
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "vehicle_state_writer", kHelp, run); }
