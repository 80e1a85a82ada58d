// ./lab bench as a whole: a benchmark that fails or hangs is named, and the others still run.
#include <cpm_test/Process.hpp>
#include <cpm_test/TempDir.hpp>
#include <cpm_test/SourceDir.hpp>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

using namespace std::chrono_literals;
using ::testing::HasSubstr;

TEST(BenchRun, AProgramThatFailsOrHangsIsNamedAndTheNextOnesStillRun)
{
    namespace fs = std::filesystem;
    cpm_test::TempDir dir;
    // bench/run.sh beside stand-ins for every benchmark program: bench_timer hangs, bench_fsm fails.
    fs::create_directories(dir.path / "bench" / "python");
    fs::copy_file(cpm_test::source_dir() + "/bench/run.sh", dir.path / "bench" / "run.sh");
    dir.write("bench/python/bench_python.py", "print('ran bench_python')\n");
    fs::create_directories(dir.path / "build" / "bin");
    for (const char* name : {"bench_latency", "bench_throughput", "bench_large", "bench_startup", "bench_timer", "bench_vehicle", "bench_firmware", "bench_fsm",
                             "bench_history_store", "bench_history_service", "bench_recording", "bench_aruco", "bench_ips", "bench_hlc", "bench_routing",
                             "bench_monitor"}) {
        const std::string body = std::string(name) == "bench_timer" ? "exec sleep 600\n"
                                 : std::string(name) == "bench_fsm" ? "echo broken >&2; exit 3\n"
                                                                    : std::string("echo ran ") + name + "\n";
        const std::string path = dir.write("build/bin/" + std::string(name), "#!/bin/sh\n" + body);
        fs::permissions(path, fs::perms::owner_all);
    }
    cpm_test::Process run({"/bin/bash", dir.file("bench/run.sh"), dir.file("build")}, {"BENCH_TIMEOUT=2"});
    EXPECT_EQ(run.wait(60s), 1) << run.output() << run.errors();
    EXPECT_THAT(run.errors(), HasSubstr("bench: bench_timer did not end within 2 s and was stopped; going on with the next"));
    EXPECT_THAT(run.errors(), HasSubstr("bench: bench_fsm failed with exit status 3; going on with the next"));
    EXPECT_THAT(run.errors(), HasSubstr("bench: 2 program(s) did not finish:\n  bench_timer: did not end within 2 s\n  bench_fsm: exit status 3\n"));
    for (const char* after : {"ran bench_vehicle", "ran bench_history_store", "ran bench_python", "ran bench_monitor"}) {
        EXPECT_THAT(run.output(), HasSubstr(after)) << "the benchmarks after the failed ones still ran";
    }
}
