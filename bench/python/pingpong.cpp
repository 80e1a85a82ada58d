// The C++ side of bench_python: `pingpong pong` echoes every VehicleState from bench_ping to
// bench_pong; `pingpong ping N` sends N, one at a time, and prints each round trip (ns), one per
// line. The Python side (pingpong.py) does exactly the same with cpm's Python package.
#include <cpm/AsyncReader.hpp>
#include <cpm/CommandLine.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/init.hpp>
#include <cpm/stamp_message.hpp>

#include <VehicleState.h>

#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <mutex>
#include <string>
#include <thread>

int main(int argc, char** argv)
{
    cpm::init(argc, argv);
    const std::string mode = argc > 1 ? argv[1] : "";
    const cpm::WriterOptions wo{.reliable = true, .history_depth = 1};
    const cpm::ReaderOptions ro{.reliable = true, .history_depth = 1};
    if (mode == "pong") {
        cpm::cli::stop_on_signals();
        cpm::Writer<VehicleState> out("bench_pong", wo);
        cpm::AsyncReader<VehicleState> in([&](std::vector<VehicleState>& s) { for (auto& x : s) (void)out.write(x); }, "bench_ping", ro);
        std::printf("ready\n");
        std::fflush(stdout);
        while (!cpm::cli::stop_requested()) std::this_thread::sleep_for(std::chrono::milliseconds(20));
        return 0;
    }
    if (mode != "ping" || argc < 3) {
        std::fprintf(stderr, "usage: pingpong pong | ping N\n");
        return 2;
    }
    const int n = std::stoi(argv[2]);
    std::mutex m;
    std::condition_variable cv;
    uint64_t back = 0;
    cpm::Writer<VehicleState> out("bench_ping", wo);
    cpm::AsyncReader<VehicleState> in([&](std::vector<VehicleState>& s) {
        std::lock_guard<std::mutex> lock(m);
        for (auto& x : s) back = x.header().create_stamp().nanoseconds();
        cv.notify_all();
    }, "bench_pong", ro);
    if (!out.wait_for_matched(1, std::chrono::seconds(10)) || !in.wait_for_matched(1, std::chrono::seconds(10))) {
        std::fprintf(stderr, "pingpong: no pong\n");
        return 1;
    }
    for (int i = 0; i < n; ++i) {
        VehicleState s;
        s.vehicle_id(1);
        const uint64_t t = cpm::get_time_ns();
        cpm::stamp_message(s, t, 0);
        (void)out.write(s);
        std::unique_lock<std::mutex> lock(m);
        if (!cv.wait_for(lock, std::chrono::seconds(2), [&] { return back == t; })) continue;  // lost: not counted
        std::printf("%llu\n", (unsigned long long)(cpm::get_time_ns() - t));
        lock.unlock();
        std::this_thread::sleep_for(std::chrono::microseconds(500));
    }
    return 0;
}
