// Publishes one VehicleState and reads it back with cpm's Reader, in one process, on this
// host only. Prints what it read; exits non-zero if nothing arrived within 5 s or what arrived
// is not what was written.
#include <cpm/Reader.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/init.hpp>
#include <cpm/stamp_message.hpp>

#include <VehicleState.h>

#include <chrono>
#include <cstdio>
#include <thread>

int main(int argc, char** argv)
{
    try {
        cpm::init(argc, argv);
        cpm::WriterOptions writer_options;
        writer_options.reliable = true;
        cpm::ReaderOptions reader_options;
        reader_options.reliable = true;
        cpm::Writer<VehicleState> writer("vehicleState", writer_options);
        cpm::Reader<VehicleState> reader("vehicleState", reader_options);
        if (!writer.wait_for_matched(1, std::chrono::seconds(5)) || !reader.wait_for_matched(1, std::chrono::seconds(5))) {
            std::fprintf(stderr, "installed_consumer: writer and reader never matched\n");
            return 1;
        }
        VehicleState state;
        state.vehicle_id(7);
        state.speed(1.25);
        const uint64_t stamp = cpm::get_time_ns();
        cpm::stamp_message(state, stamp, 0);
        if (!writer.write(state)) {
            std::fprintf(stderr, "installed_consumer: the write failed\n");
            return 1;
        }

        const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
        while (std::chrono::steady_clock::now() < deadline) {
            auto result = reader.get_sample(cpm::get_time_ns());
            if (result.valid) {
                const auto& got = result.sample;
                if (got.vehicle_id() != 7 || got.speed() != 1.25 || got.header().create_stamp().nanoseconds() != stamp) {
                    std::fprintf(stderr, "installed_consumer: read vehicle %d speed %.17g stamp %llu, wrote vehicle 7 speed 1.25 stamp %llu\n",
                                 int(got.vehicle_id()), got.speed(), (unsigned long long)got.header().create_stamp().nanoseconds(),
                                 (unsigned long long)stamp);
                    return 1;
                }
                std::printf("installed_consumer: read vehicle %d speed %.2f age %.3f ms\n", int(result.sample.vehicle_id()),
                            result.sample.speed(), double(result.age_ns) * 1e-6);
                return 0;
            }
            std::this_thread::sleep_for(std::chrono::milliseconds(5));
        }
        std::fprintf(stderr, "installed_consumer: no sample within 5 s\n");
        return 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "installed_consumer: %s\n", e.what());
        return 1;
    }
}
