#pragma once
#include <string>

namespace cpm {

/// Whether a program runs its loops in real time (`--realtime`, as cpm_lab's vehicle and timers).
///
/// Real time means: memory locked (mlockall of what the process has and will have, each page
/// locked once touched, so thread stacks are not filled up front) and the threads that keep a
/// car's period, the timer thread, the bridge's serial loop and firmware_sim's line readers, at a
/// SCHED_FIFO priority (see realtime_priority). Fast DDS's own threads keep their normal priority.
enum class Realtime
{
    off,       ///< normal scheduling
    on,        ///< real time where permitted; else one message naming what is missing, then without
    required,  ///< real time or refuse: programs exit 2 (cpm::cli::UsageError)
};

/// The SCHED_FIFO priority (1..99, higher first) of each real-time thread cpm starts. Above
/// a PREEMPT_RT kernel's interrupt threads (50), below its watchdog and migration threads (99).
namespace realtime_priority {
/// A Timer's thread (start() or start_async()): the period of every node, firmware_sim's
/// microcontrollers, the bridge under simulated time.
inline constexpr int timer = 60;
/// The bridge's serial loop (one per car): it answers the car's state packets as they come,
/// before the timers of the same computer.
inline constexpr int serial_loop = 70;
/// firmware_sim's line reader (one per car): takes what the host wrote off the pseudo-terminal,
/// a read that may wait for the kernel's worker, so the microcontroller's timer never does; above
/// the timer, so what came in is there before its next tick.
inline constexpr int line_reader = 65;
}  // namespace realtime_priority

/// "off", "on" or "required".
const char* to_string(Realtime mode);

/// Reads `--realtime`'s value: on/true/yes/1, off/false/no/0, required. Throws cpm::Error
/// naming `source` and the text otherwise.
Realtime parse_realtime(const std::string& text, const std::string& source);

/// What keeps this process from real time at `priority`: empty when it may lock its memory
/// and run SCHED_FIFO threads at that priority; else one sentence per missing privilege, each
/// with how to grant it (limits.conf line, capability, systemd setting). Tries it on a
/// short-lived thread, so it also sees a cgroup without real-time budget.
std::string realtime_missing(int priority = realtime_priority::serial_loop);

/// Locks the process's memory now and for its future mappings (each page once touched).
/// Empty on success, else what is missing and how to grant it. Done once per process; a
/// finite RLIMIT_MEMLOCK without CAP_IPC_LOCK is refused (future allocations would fail at it).
std::string lock_memory();

/// While it lives, the calling thread runs SCHED_FIFO at `priority` (the thread's previous
/// policy comes back when it goes). With Realtime::off it does nothing. Where not permitted:
/// with Realtime::on it runs on as it was (the reason was said by cpm::init, or here once per
/// process); with Realtime::required it throws cpm::Error naming `what` and the reason.
class RealtimeThread
{
public:
    RealtimeThread(Realtime mode, int priority, const std::string& what);
    ~RealtimeThread();
    RealtimeThread(const RealtimeThread&) = delete;
    RealtimeThread& operator=(const RealtimeThread&) = delete;

    /// Whether the thread runs SCHED_FIFO now.
    bool active() const { return active_; }

private:
    bool active_ = false;
    int old_policy_ = 0;
    int old_priority_ = 0;
};

}  // namespace cpm
