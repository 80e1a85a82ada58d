// Reads every vehicle's newest valid VehicleState once a second with one MultiVehicleReader
// and prints it with its age (now - valid_after_stamp).
//
//   vehicle_state_monitor [--vehicles N] [--seconds S] [--dds_domain D]
#include <cpm/CommandLine.hpp>
#include <cpm/MultiVehicleReader.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/init.hpp>

#include <VehicleState.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <thread>

namespace {

const char* kHelp =
    "usage: vehicle_state_monitor [--vehicles N (1..255, default 4)] [--seconds S (default 5)] [--dds_domain D]\n"
    "Prints each vehicle's newest valid state on topic 'vehicleState' once a second; exits 0 when a\n"
    "report had a valid state for every vehicle, 2 when none had.\n";

int run(int argc, char** argv)
{
    const auto flags = cpm::cli::parse_flags(argc, argv, {{"--vehicles", true}, {"--seconds", true}}, "vehicle_state_monitor");
    const int vehicles = int(cpm::cli::parse_integer("--vehicles", flags.get("--vehicles", "4"), 1, 255));
    const int seconds = int(cpm::cli::parse_integer("--seconds", flags.get("--seconds", "5"), 1, 3600));
    cpm::init(argc, argv);
    cpm::MultiVehicleReader<VehicleState> reader("vehicleState", vehicles);

    int reports_with_all = 0;
    double max_age_ms = 0;
    for (int s = 1; s <= seconds; ++s) {
        std::this_thread::sleep_for(std::chrono::seconds(1));
        const uint64_t now = cpm::get_time_ns();
        std::printf("t=%ds  vehicle      x [m]      y [m]   yaw [rad]  speed [m/s]   age [ms]  since created [ms]\n", s);
        int valid = 0;
        for (const auto& [id, result] : reader.get_samples(now)) {
            if (!result.valid) {
                std::printf("       %7d   (no valid sample yet)\n", int(id));
                continue;
            }
            ++valid;
            const double age_ms = double(result.age_ns) * 1e-6;
            max_age_ms = std::max(max_age_ms, age_ms);
            const auto& p = result.sample.pose();
            const double since_created_ms = double(now - result.sample.header().create_stamp().nanoseconds()) * 1e-6;
            std::printf("       %7d %10.3f %10.3f %11.3f %12.2f %10.1f %19.1f\n", int(id), p.x(), p.y(), p.yaw(),
                        result.sample.speed(), age_ms, since_created_ms);
        }
        if (valid == vehicles) ++reports_with_all;
    }
    std::printf("monitor: %d of %d reports had a valid state for all %d vehicles; largest age %.1f ms\n",
                reports_with_all, seconds, vehicles, max_age_ms);
    return reports_with_all > 0 ? 0 : 2;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "vehicle_state_monitor", kHelp, run); }
