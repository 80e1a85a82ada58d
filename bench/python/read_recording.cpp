// The C++ side of bench_python's recording case: a topic of a recording read into columns (the
// times and every field of VehicleState) with cpm::HistoryClient::open_recording, as Python's
// cpm.open_recording(...).table(...) does. Prints the samples read and the seconds taken.
#include <cpm/HistoryClient.hpp>

#include <VehicleState.h>

#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

int main(int argc, char** argv)
{
    if (argc < 2) {
        std::fprintf(stderr, "usage: read_recording FILE\n");
        return 2;
    }
    const auto t0 = std::chrono::steady_clock::now();
    auto run = cpm::HistoryClient::open_recording(argv[1]);
    std::vector<uint64_t> commit, data;
    std::vector<double> x, y, yaw, speed, odometer, battery;
    uint64_t from = 0;
    for (;;) {
        auto page = run.range_of<VehicleState>("vehicleState", 1, from, UINT64_MAX, cpm::HistoryBy::commit, 1000);
        for (const auto& r : page.samples) {
            commit.push_back(r.commit_ns);
            data.push_back(r.data_ns);
            x.push_back(r.sample.pose().x());
            y.push_back(r.sample.pose().y());
            yaw.push_back(r.sample.pose().yaw());
            speed.push_back(r.sample.speed());
            odometer.push_back(r.sample.odometer_distance());
            battery.push_back(r.sample.battery_voltage());
        }
        if (!page.truncated || page.samples.empty()) break;
        from = page.samples.back().commit_ns + 1;
    }
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::printf("%zu %.4f\n", commit.size(), s);
    return 0;
}
