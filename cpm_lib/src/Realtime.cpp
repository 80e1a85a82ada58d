#include <cpm/Realtime.hpp>

#include <cpm/Error.hpp>
#include <cpm/init.hpp>

#include "realtime_internal.hpp"

#include <pthread.h>
#include <pwd.h>
#include <sched.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <mutex>
#include <thread>

namespace cpm {
namespace {

constexpr int kCapIpcLock = 14;  // linux/capability.h
constexpr int kCapSysNice = 23;

bool has_capability(int capability)
{
    std::ifstream status("/proc/self/status");
    std::string line;
    while (std::getline(status, line)) {
        if (line.rfind("CapEff:", 0) != 0) continue;
        const unsigned long long mask = std::strtoull(line.c_str() + 7, nullptr, 16);
        return (mask >> capability) & 1ull;
    }
    return false;
}

std::string user_name()
{
    const passwd* pw = getpwuid(geteuid());
    return pw != nullptr ? pw->pw_name : std::to_string(geteuid());
}

std::string limit_text(rlim_t value, const char* unit, rlim_t divisor = 1)
{
    if (value == RLIM_INFINITY) return "unlimited";
    return std::to_string(value / divisor) + unit;
}

std::string fifo_missing(int priority, int error)
{
    rlimit rtprio{};
    getrlimit(RLIMIT_RTPRIO, &rtprio);
    const std::string head = "SCHED_FIFO priority " + std::to_string(priority) + " is not permitted";
    if (error != EPERM) return head + " (" + std::strerror(error) + ")";
    if (has_capability(kCapSysNice) || rtprio.rlim_cur == RLIM_INFINITY || rtprio.rlim_cur >= rlim_t(priority)) {
        return head + " although CAP_SYS_NICE or RLIMIT_RTPRIO (" + limit_text(rtprio.rlim_cur, "") +
               ") allows it: the process's control group has no real-time budget (cgroup v1 cpu.rt_runtime_us is 0; "
               "with docker, run it with --cpu-rt-runtime=950000 and --ulimit rtprio=99)";
    }
    return head + ": RLIMIT_RTPRIO is " + limit_text(rtprio.rlim_cur, "") +
           " and the process lacks CAP_SYS_NICE; grant it with the line '" + user_name() +
           " - rtprio 99' in /etc/security/limits.conf (then log in again), LimitRTPRIO=99 in a systemd unit, "
           "or `setcap cap_sys_nice+ep PROGRAM`";
}

std::string memlock_grant()
{
    return "; grant it with the line '" + user_name() +
           " - memlock unlimited' in /etc/security/limits.conf (then log in again), LimitMEMLOCK=infinity in a "
           "systemd unit, or `setcap cap_ipc_lock+ep PROGRAM`";
}

// Locking every future mapping under a finite limit would make each allocation beyond it fail:
// only with CAP_IPC_LOCK or no limit.
std::string memlock_missing()
{
    rlimit memlock{};
    getrlimit(RLIMIT_MEMLOCK, &memlock);
    if (has_capability(kCapIpcLock) || memlock.rlim_cur == RLIM_INFINITY) return "";
    return "memory cannot be locked: RLIMIT_MEMLOCK is " + limit_text(memlock.rlim_cur, " kB", 1024) +
           " and the process lacks CAP_IPC_LOCK (with a finite limit, every allocation beyond it would fail)" +
           memlock_grant();
}

std::mutex g_lock_mutex;
bool g_locked = false;
std::atomic<bool> g_fifo_said{false};

}  // namespace

const char* to_string(Realtime mode)
{
    switch (mode) {
        case Realtime::off: return "off";
        case Realtime::on: return "on";
        case Realtime::required: return "required";
    }
    return "?";
}

Realtime parse_realtime(const std::string& text, const std::string& source)
{
    if (text == "on" || text == "true" || text == "yes" || text == "1") return Realtime::on;
    if (text == "off" || text == "false" || text == "no" || text == "0") return Realtime::off;
    if (text == "required") return Realtime::required;
    throw Error(source + ": '" + text + "' is not one of on, off, required");
}

std::string lock_memory()
{
    std::lock_guard<std::mutex> lock(g_lock_mutex);
    if (g_locked) return "";
    if (std::string missing = memlock_missing(); !missing.empty()) return missing;
    if (mlockall(MCL_CURRENT | MCL_FUTURE | MCL_ONFAULT) != 0) {
        return std::string("memory cannot be locked: mlockall: ") + std::strerror(errno) + memlock_grant();
    }
    g_locked = true;
    return "";
}

std::string realtime_missing(int priority)
{
    std::string missing = memlock_missing();
    // Tried on a thread of its own: the caller's scheduling stays as it is.
    int error = 0;
    std::thread probe([&] {
        sched_param param{};
        param.sched_priority = priority;
        error = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param);
    });
    probe.join();
    if (error != 0) missing += (missing.empty() ? "" : "; ") + fifo_missing(priority, error);
    return missing;
}

RealtimeThread::RealtimeThread(Realtime mode, int priority, const std::string& what)
{
    if (mode == Realtime::off) return;
    sched_param old{};
    pthread_getschedparam(pthread_self(), &old_policy_, &old);
    old_priority_ = old.sched_priority;
    sched_param param{};
    param.sched_priority = priority;
    const int error = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param);
    if (error == 0) {
        active_ = true;
        return;
    }
    const std::string reason = fifo_missing(priority, error);
    if (mode == Realtime::required) throw Error(what + ": --realtime=required: " + reason);
    // cpm::init said it already when --realtime was given; a program that asked in code hears it once.
    if (!g_fifo_said.exchange(true) && init_settings().realtime == Realtime::off) {
        std::fprintf(stderr, "%s: runs without real time: %s\n", what.c_str(), reason.c_str());
    }
}

RealtimeThread::~RealtimeThread()
{
    if (!active_) return;
    sched_param param{};
    param.sched_priority = old_priority_;
    pthread_setschedparam(pthread_self(), old_policy_, &param);
}

namespace detail {

void start_realtime(Realtime mode, const std::string& node_id)
{
    if (mode == Realtime::off) return;
    std::string missing = realtime_missing(realtime_priority::serial_loop);
    if (missing.empty()) missing = lock_memory();
    if (missing.empty()) return;
    if (mode == Realtime::required) throw Error("--realtime=required: not permitted here: " + missing);
    g_fifo_said = true;
    std::fprintf(stderr, "%s: --realtime: runs without real time: %s\n", node_id.c_str(), missing.c_str());
}

void run_at_normal_priority()
{
    int policy = SCHED_OTHER;
    sched_param param{};
    if (pthread_getschedparam(pthread_self(), &policy, &param) != 0 || policy == SCHED_OTHER) return;
    param.sched_priority = 0;
    pthread_setschedparam(pthread_self(), SCHED_OTHER, &param);
}

}  // namespace detail
}  // namespace cpm
