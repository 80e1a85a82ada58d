#pragma once
// cpm::ChildProcess — starts a program and supervises it: where its output goes, whether it
// still runs, how it ended, and stopping it (SIGTERM, then SIGKILL after a grace period). The
// destructor stops a child still running, so no error path leaves one behind. Used by the cpm
// command (`cpm vehicle sim`), the tests and the benchmarks.
//
//   cpm::ChildProcess sim({.argv = {cpm::sibling_executable("firmware_sim"), "--vehicle_id", "3"},
//                          .capture_stdout = true, .die_with_parent = true});
//   auto line = sim.read_line();                  // "device: /dev/pts/4"
//   ...
//   cpm::ExitStatus end = sim.stop();             // end.describe(): "exited with code 0"
//
// Not thread-safe; move it, never copy it.
#include <chrono>
#include <optional>
#include <string>
#include <vector>

namespace cpm {

struct ProcessOptions
{
    std::vector<std::string> argv;  ///< argv[0]: the program's path (see sibling_executable)
    std::vector<std::string> env;   ///< added to this process's environment, "NAME=value"
    std::string stdout_path;        ///< "": this process's stdout (unless captured)
    std::string stderr_path;        ///< "": this process's stderr; the same path as stdout_path: one file for both
    bool append_output = false;     ///< append to the output files instead of starting them afresh
    bool capture_stdout = false;    ///< read it with read_line()
    bool pipe_stdin = false;        ///< its stdin is a pipe from this process (write_stdin, close_stdin); else /dev/null's or ours
    bool own_process_group = false; ///< signals then reach the programs it starts too
    bool die_with_parent = false;   ///< SIGTERM when this process dies, even by SIGKILL
};

/// How a child ended.
struct ExitStatus
{
    int code = -1;    ///< its exit code, when it exited
    int signal = 0;   ///< the signal that ended it, or 0
    bool ok() const { return signal == 0 && code == 0; }
    /// "exited with code 3", "killed by SIGSEGV".
    std::string describe() const;
};

class ChildProcess
{
public:
    /// Starts the program. Throws cpm::Error naming the program when it does not exist or is
    /// not executable, or when an output file cannot be opened.
    explicit ChildProcess(ProcessOptions options);
    /// Stops it if it still runs (stop()).
    ~ChildProcess();
    ChildProcess(ChildProcess&& other) noexcept;
    ChildProcess& operator=(ChildProcess&& other) noexcept;
    ChildProcess(const ChildProcess&) = delete;
    ChildProcess& operator=(const ChildProcess&) = delete;

    int pid() const { return pid_; }
    const std::string& program() const { return program_; }
    /// Whether it still runs (reaps it when it has ended).
    bool running();
    /// Its end, once it has ended (without waiting).
    std::optional<ExitStatus> ended();
    /// Waits up to `timeout` for it to end.
    std::optional<ExitStatus> wait(std::chrono::milliseconds timeout);
    /// Sends a signal (to its process group when it has its own).
    void signal(int sig);
    /// Asks it to stop with `sig` (SIGINT, SIGTERM), then SIGCONT: a frozen process (SIGSTOP,
    /// Ctrl-Z) acts on a signal only once continued (systemd stops services so too).
    void ask_to_stop(int sig);
    /// SIGTERM (ask_to_stop), then SIGKILL if it has not ended within `grace`; waits for the end.
    ExitStatus stop(std::chrono::milliseconds grace = std::chrono::seconds(3));
    /// The next line of its captured stdout (without the newline), blocking; nullopt at its end.
    std::optional<std::string> read_line();
    /// The captured stdout's file descriptor (-1 when not captured), for poll().
    int stdout_fd() const { return out_fd_; }
    /// Writes to its stdin (ProcessOptions::pipe_stdin); false when it no longer reads it.
    bool write_stdin(const std::string& text);
    /// Closes its stdin: it reads the end of its input (a remote process's wrapper then stops it).
    void close_stdin();

private:
    void release();
    std::string program_;
    int pid_ = -1;
    int out_fd_ = -1;
    int in_fd_ = -1;
    bool group_ = false;
    std::optional<ExitStatus> end_;
};

/// The directory of the running program (from /proc/self/exe).
std::string executable_dir();
/// A program installed (or built) beside the running one: executable_dir()/name. Throws
/// cpm::Error naming the path when it is missing or not executable.
std::string sibling_executable(const std::string& name);
/// A program on $PATH (/usr/bin:/bin when unset): its path, or "" when none is executable.
std::string program_on_path(const std::string& name);

}  // namespace cpm
