// A cpm program that ends cleanly leaves nothing in /dev/shm: Fast DDS's shared-memory segment
// (4 MB of RAM each), its port files and cpm's own port markers go with it. The programs are
// real processes; the files are those each one had open or mapped while it ran, so tests
// running beside this one (other domains, other files) do not disturb the count.
#include <cpm_test/Isolation.hpp>
#include <cpm_test/Process.hpp>
#include <cpm_test/TempDir.hpp>
#include <cpm_test/SourceDir.hpp>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <csignal>
#include <cstdio>
#include <cstring>
#include <dirent.h>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>
#include <thread>
#include <unistd.h>
#include <vector>

using namespace std::chrono_literals;
using cpm_test::built_program;
using cpm_test::Process;
namespace fs = std::filesystem;

namespace {

/// The /dev/shm files a process has open or mapped now.
std::set<std::string> shm_files_of(int pid)
{
    std::set<std::string> files;
    std::ifstream maps("/proc/" + std::to_string(pid) + "/maps");
    for (std::string line; std::getline(maps, line);) {
        const auto at = line.find("/dev/shm/");
        if (at != std::string::npos) files.insert(line.substr(at));
    }
    const std::string fd_dir = "/proc/" + std::to_string(pid) + "/fd";
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(fd_dir, ec)) {
        const auto target = fs::read_symlink(e.path(), ec);
        if (!ec && target.string().rfind("/dev/shm/", 0) == 0) files.insert(target.string());
    }
    std::set<std::string> named;  // a file unlinked while mapped reads "… (deleted)": it is gone already
    for (const auto& f : files) named.insert(f.substr(0, f.find(" (deleted)")));
    return named;
}

/// The files of this test's domain (ports 7400 + 250 * domain + 0..249) that name a port:
/// Fast DDS's fastrtps_port<N>, its _el lock and semaphore, and cpm's markers of dead ports.
std::set<std::string> domain_port_files(int domain)
{
    const unsigned first = 7400u + 250u * unsigned(domain);
    std::set<std::string> files;
    DIR* dir = ::opendir("/dev/shm");
    if (!dir) return files;
    while (const dirent* e = ::readdir(dir)) {
        const std::string name = e->d_name;
        for (const char* prefix : {"fastrtps_port", "sem.fastrtps_port", "cpm_dead_fastrtps_port"}) {
            if (name.rfind(prefix, 0) != 0) continue;
            const unsigned port = unsigned(std::strtoul(name.c_str() + std::strlen(prefix), nullptr, 10));
            if (port >= first && port < first + 250u) files.insert(name);
        }
    }
    ::closedir(dir);
    return files;
}

/// The processes whose parent is `pid`.
std::vector<int> children_of(int pid)
{
    std::vector<int> out;
    std::error_code ec;
    for (const auto& e : fs::directory_iterator("/proc", ec)) {
        const std::string name = e.path().filename().string();
        if (name.find_first_not_of("0123456789") != std::string::npos) continue;
        std::ifstream stat(e.path() / "stat");
        std::string line;
        std::getline(stat, line);
        const auto close = line.rfind(')');
        int parent = 0;
        if (close != std::string::npos && std::sscanf(line.c_str() + close + 1, " %*c %d", &parent) == 1 && parent == pid) {
            out.push_back(std::stoi(name));
        }
    }
    return out;
}

/// Waits up to 90 s for a cpm lab run to end, collecting every 50 ms the /dev/shm files it and
/// its processes use (and their pids in `seen`); its exit code (-1: it did not end).
int watch_lab_run(Process& run, std::set<std::string>& used, std::set<int>* seen = nullptr)
{
    const auto until = std::chrono::steady_clock::now() + 90s;
    while (std::chrono::steady_clock::now() < until) {
        for (auto& f : shm_files_of(run.pid())) used.insert(f);
        for (int pid : children_of(run.pid())) {
            if (seen) seen->insert(pid);
            for (auto& f : shm_files_of(pid)) used.insert(f);
        }
        if (const int code = run.wait(50ms); code != -1) return code;
    }
    return run.wait(0ms);
}

/// Runs `argv` until `ended` says it is time to stop it with `signal` (0: it ends by itself),
/// then checks that it exited 0 and that no file it used in /dev/shm is left.
void expect_nothing_left(int domain, std::vector<std::string> argv, int signal, std::chrono::milliseconds run_for)
{
    SCOPED_TRACE(argv[0] + (signal ? " stopped by signal " + std::to_string(signal) : " ending by itself"));
    Process sut(argv);
    std::set<std::string> used;
    const auto until = std::chrono::steady_clock::now() + run_for;
    int code = -2;
    while (std::chrono::steady_clock::now() < until) {
        for (auto& f : shm_files_of(sut.pid())) used.insert(f);
        if (!signal && (code = sut.wait(50ms)) != -1) break;
        if (signal) std::this_thread::sleep_for(50ms);
    }
    if (signal) {
        sut.kill(signal);
        code = sut.wait(30s);
    } else if (code == -1) {
        code = sut.wait(30s);
    }
    ASSERT_EQ(code, 0) << sut.errors();
    EXPECT_GE(used.size(), 3u) << "it used shared memory (a segment, a port, its lock) while it ran";
    for (const auto& f : used) EXPECT_FALSE(fs::exists(f)) << f << " is left behind";
    EXPECT_EQ(domain_port_files(domain), std::set<std::string>{}) << "no port file or marker of its domain is left";
}

}  // namespace

TEST(SharedMemoryLeftovers, AProgramThatReturnsFromMainLeavesNothing)
{
    expect_nothing_left(cpm_test::test_domain_id(), {built_program("vehicle_state_writer"), "--vehicles", "1", "--seconds", "2"}, 0, 20s);
}

TEST(SharedMemoryLeftovers, TheHistoryStoppedByCtrlCLeavesNothing)
{
    expect_nothing_left(cpm_test::test_domain_id(), {built_program("cpm_history")}, SIGINT, 3s);  // it logs: the log's writer goes too
}

TEST(SharedMemoryLeftovers, TheMonitorStoppedBySigtermLeavesNothing)
{
    expect_nothing_left(cpm_test::test_domain_id(), {built_program("cpm"), "monitor", "--port", "0"}, SIGTERM, 3s);
}

TEST(SharedMemoryLeftovers, ALabRunLeavesNothingOfItsDomain)
{
    const int domain = cpm_test::test_domain_id();
    cpm_test::TempDir dir;
    // Shared memory on, as in real time (a simulated run does without it unless told).
    Process run({built_program("cpm"), "lab", "run", cpm_test::source_dir() + "/scenarios/labs/corridor.yaml", "--duration", "2s",
                 "--out", dir.file("run"), "--monitor", "off", "--dds_shared_memory", "on"});
    std::set<std::string> used;
    ASSERT_EQ(watch_lab_run(run, used), 0) << run.errors();
    EXPECT_FALSE(used.empty()) << "the run's processes used shared memory";
    // Every process of the run (history, simulator, bridge, state machine) ended on the run's
    // SIGINT or by itself: none of their ports, locks or cpm's markers stays.
    EXPECT_EQ(domain_port_files(domain), std::set<std::string>{});
}

TEST(SharedMemoryLeftovers, ASimulatedLabRunSharesNoMemoryUnlessTold)
{
    // Its processes talk over UDP loopback alone: Fast DDS 2.9 would send every sample both ways.
    cpm_test::TempDir dir;
    Process run({built_program("cpm"), "lab", "run", cpm_test::source_dir() + "/scenarios/labs/corridor.yaml", "--duration", "2s",
                 "--out", dir.file("run"), "--monitor", "off"});
    std::set<std::string> used;
    std::set<int> seen;
    ASSERT_EQ(watch_lab_run(run, used, &seen), 0) << run.errors();
    EXPECT_GE(seen.size(), 4u) << "history, simulator, bridge and state machine were looked at";
    EXPECT_EQ(used, std::set<std::string>{});
    EXPECT_THAT(run.output() + run.errors(), ::testing::HasSubstr("(UDP only, no shared memory)"));
}
