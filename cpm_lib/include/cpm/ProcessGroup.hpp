#pragma once
// cpm::ProcessGroup — the processes of one job (a lab run, `cpm vehicle sim`, a test) supervised
// together: each started from a spec, its end noticed and restarted when the spec says so, all
// stopped in their stop order on every way out, a log's last lines for messages.
//
//   cpm::ProcessGroup group;
//   group.start({.name = "firmware_sim 3", .argv = {...}, .capture_stdout = true, .stop_order = 2});
//   group.start({.name = "vehicle_bridge 3", .argv = {...}, .log = "bridge.log", .restart = true, .stop_order = 1});
//   for (;;) for (const auto& e : group.poll()) { ... e.name, e.end.describe(), e.restarted ... }
//   group.stop_all();   // bridges (order 1) first, then the simulators; also by the destructor
//
// Not thread-safe: one thread owns the group.
#include <cpm/ChildProcess.hpp>
#include <cpm/RemoteHost.hpp>

#include <chrono>
#include <condition_variable>
#include <deque>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace cpm {

/// One process of a group.
struct ProcessSpec
{
    std::string name;               ///< unique in the group: "fsm_5", "vehicle_bridge 3"
    std::vector<std::string> argv;  ///< argv[0]: the program's path
    std::vector<std::string> env;   ///< added to the environment, "NAME=value"
    std::string log;                ///< its stdout and stderr go to this file; "": this process's own
    bool capture_stdout = false;    ///< read it with read_line() (then only stderr goes to the log)
    bool restart = false;           ///< started again (log appended to) when it ends other than with exit 0
    int stop_order = 0;             ///< stopped in ascending order; equal orders together
    /// In a process group of its own, so that a signal reaches what it starts too. false: it
    /// shares this process's group, and a signal to that group (Ctrl-C, Ctrl-Z, a supervisor's
    /// SIGSTOP) reaches it as it reaches this process.
    bool own_process_group = true;
    /// How long it may take to end on SIGINT before SIGTERM and SIGKILL follow. A remote one's
    /// are sent on its host; its ssh is ended here only 6 s after its grace (then told as
    /// killed by SIGTERM, not as a lost host).
    std::chrono::milliseconds stop_grace{5000};
    /// Where it runs: this host (the default), or another reached with ssh (argv[0] is then a
    /// path on that host). A remote process runs under `cpm host run` in a process group of its
    /// own there; its output comes back into `log`; stopping it closes its ssh's input.
    RemoteHost host;
};

/// A process of the group that ended.
struct ProcessEvent
{
    std::string name;
    ExitStatus end;
    bool restarted = false;  ///< its spec said restart, and it was started again
    int restarts = 0;        ///< times it has been restarted so far
    std::string host;        ///< the host it ran on ("" this one)
    /// It ran on another host and ssh ended without its end: the host was lost or not reached.
    bool host_lost = false;
    /// "exited with code 3", "killed by SIGSEGV on car5", "lost with host car5 (ssh: …)".
    std::string describe() const;
};

class ProcessGroup
{
public:
    ProcessGroup() = default;
    /// Stops every process still running, in stop order.
    ~ProcessGroup();
    ProcessGroup(const ProcessGroup&) = delete;
    ProcessGroup& operator=(const ProcessGroup&) = delete;

    /// Starts a process (in its own process group unless its spec says otherwise), ended with
    /// this process if it dies. Throws cpm::Error naming the spec when its name is taken,
    /// its host is not this one, or the program cannot be started.
    ChildProcess& start(ProcessSpec spec);
    /// The processes that ended since the last call, each once; those whose spec says restart
    /// (and that did not exit 0) are started again before this returns.
    std::vector<ProcessEvent> poll();
    /// Stops it if it runs (as stop_all does), then starts it again with its spec, its log
    /// appended to. Throws cpm::Error for a name not in the group.
    ChildProcess& restart(const std::string& name);
    /// Stops every process still running: SIGINT to each of the lowest stop order, waits up to
    /// each one's grace, then SIGTERM and SIGKILL; then the next order. Returns every process's
    /// end (of those that ended before too), in start order.
    std::vector<ProcessEvent> stop_all();

    /// The process by name, or nullptr.
    ChildProcess* find(const std::string& name);
    /// How it ended, once it has (from poll or stop_all).
    std::optional<ExitStatus> end_of(const std::string& name) const;
    int restarts_of(const std::string& name) const;
    /// The last `n` lines of its log, each indented by four spaces ("" without a log).
    std::string tail(const std::string& name, size_t n = 10) const;
    /// Its whole log so far ("" without a log).
    std::string log_text(const std::string& name) const;
    /// The names, in start order.
    std::vector<std::string> names() const;

private:
    struct Member
    {
        ProcessSpec spec;
        std::optional<ChildProcess> child;
        std::optional<ExitStatus> end;
        int restarts = 0;
    };
    Member* member(const std::string& name);
    const Member* member(const std::string& name) const;
    void launch(Member& m, bool again);
    void interrupt(Member& m);
    /// Every second, a line to each remote process's input: its `cpm host run` stops it when
    /// none comes for kRemoteLease (a host cut off from the run stops what the run started).
    void keep_remotes_alive();
    static void stop(Member& m);
    static ExitStatus as_told(const Member& m, const ExitStatus& end);
    static ProcessEvent event_of(const Member& m, const ExitStatus& end);
    std::deque<Member> members_;  // a deque: references to members stay valid
    std::mutex stdin_mutex_;      // members_'s shape and the remote ones' inputs, shared with the keepalive
    std::condition_variable keepalive_wake_;
    bool keepalive_ending_ = false;
    std::thread keepalive_;       // started with the first remote process
};

/// The last `n` lines of a text file, each indented by four spaces.
std::string tail_of_file(const std::string& path, size_t n);

}  // namespace cpm
