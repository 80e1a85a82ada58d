#include "bench_common.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <cstdio>
#include <fstream>
#include <thread>

#include <fcntl.h>
#include <sys/utsname.h>
#include <sys/wait.h>
#include <unistd.h>

extern char** environ;

namespace bench {

Stats stats_of(std::vector<double> v)
{
    Stats s;
    s.n = v.size();
    if (v.empty()) return s;
    std::sort(v.begin(), v.end());
    auto at = [&](double q) { return v[std::min(v.size() - 1, static_cast<size_t>(q * double(v.size())))]; };
    s.min = v.front();
    s.p50 = at(0.50);
    s.p90 = at(0.90);
    s.p99 = at(0.99);
    s.max = v.back();
    return s;
}

void print_header(const std::string& what)
{
    std::printf("\n%s\n%-44s %8s %9s %9s %9s %9s %10s\n", what.c_str(), "case", "n", "min", "p50", "p90", "p99", "max");
}

void print_row(const std::string& label, const Stats& s)
{
    std::printf("%-44s %8zu %9.1f %9.1f %9.1f %9.1f %10.1f\n", label.c_str(), s.n, s.min, s.p50, s.p90, s.p99, s.max);
    std::fflush(stdout);
}

void print_ratio(const std::string& label, const Stats& ours, const Stats& reference)
{
    std::printf("%-44s p50 ratio %.2f   p99 ratio %.2f\n", label.c_str(), ours.p50 / reference.p50, ours.p99 / reference.p99);
    std::fflush(stdout);
}

void print_machine(const std::string& settings)
{
    utsname u{};
    uname(&u);
    std::string cpu = "?";
    std::ifstream cpuinfo("/proc/cpuinfo");
    for (std::string line; std::getline(cpuinfo, line);) {
        if (line.rfind("model name", 0) == 0) {
            cpu = line.substr(line.find(':') + 2);
            break;
        }
    }
    std::printf("machine: %s, %u cores, %s %s\nsettings: %s\n", cpu.c_str(), std::thread::hardware_concurrency(),
                u.sysname, u.release, settings.c_str());
}

int spawn(const std::vector<std::string>& argv, const std::vector<std::string>& env, const std::string& out_path,
          const std::string& err_path)
{
    std::vector<std::string> args = argv, envs;
    for (char** e = environ; *e; ++e) envs.emplace_back(*e);
    envs.insert(envs.end(), env.begin(), env.end());
    const int pid = fork();
    if (pid == 0) {
        if (!out_path.empty()) {
            const int fd = open(out_path.c_str(), O_CREAT | O_TRUNC | O_WRONLY, 0644);
            dup2(fd, STDOUT_FILENO);
        }
        if (!err_path.empty()) {
            const int fd = open(err_path.c_str(), O_CREAT | O_TRUNC | O_WRONLY, 0644);
            dup2(fd, STDERR_FILENO);
        }
        close_range(3, ~0u, 0);  // keep our DDS shared-memory lock files out of the child
        std::vector<char*> a, e;
        for (auto& s : args) a.push_back(s.data());
        a.push_back(nullptr);
        for (auto& s : envs) e.push_back(s.data());
        e.push_back(nullptr);
        execve(a[0], a.data(), e.data());
        _exit(127);
    }
    return pid;
}

int spawn_self(const std::vector<std::string>& args)
{
    char self[4096];
    const ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
    self[n > 0 ? n : 0] = '\0';
    std::vector<std::string> argv{self};
    argv.insert(argv.end(), args.begin(), args.end());
    return spawn(argv, {}, "");
}

int wait_child(int pid, double timeout_s)
{
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    int status = 0;
    while (waitpid(pid, &status, WNOHANG) == 0) {
        if (std::chrono::steady_clock::now() > deadline) {
            kill(pid, SIGKILL);
            waitpid(pid, &status, 0);
            return -1;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string cyclone_loopback_env() { return "CYCLONEDDS_URI=file://" CPM_CYCLONE_LOOPBACK_XML; }

bool data_sharing()
{
    const char* value = std::getenv("BENCH_DATA_SHARING");
    return value != nullptr && std::string(value) == "1";
}

std::string arg(int argc, char** argv, const std::string& name, const std::string& fallback)
{
    for (int i = 1; i + 1 < argc; ++i) {
        if (argv[i] == name) return argv[i + 1];
    }
    return fallback;
}

}  // namespace bench
