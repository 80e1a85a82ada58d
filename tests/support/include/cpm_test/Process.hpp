#pragma once
#include <cpm/ChildProcess.hpp>

#include <chrono>
#include <string>
#include <vector>

namespace cpm_test {

/// A child process started by a test (a cpm::ChildProcess in its own process group), with its
/// stdout and stderr captured to files. The destructor kills it (SIGTERM, then SIGKILL) and
/// reaps it, so a failing test never leaves it behind.
class Process
{
public:
    /// Starts `argv[0]` with the given arguments and extra environment ("NAME=value").
    explicit Process(std::vector<std::string> argv, std::vector<std::string> env = {});
    ~Process();
    Process(const Process&) = delete;
    Process& operator=(const Process&) = delete;

    /// Waits for the process to exit; returns its exit code, or -1 on timeout/signal.
    int wait(std::chrono::milliseconds timeout);
    /// Everything it has written to stdout so far.
    std::string output() const;
    /// Everything it has written to stderr so far.
    std::string errors() const;
    void kill(int signal);
    int pid() const { return child_.pid(); }

private:
    std::string out_path_;
    std::string err_path_;
    cpm::ChildProcess child_;
};

/// A file's whole text ("" when it cannot be read).
std::string file_text(const std::string& path);

/// The pid of a running process whose command line holds `needle` and, unless `tag` is "",
/// whose environment holds the entry `tag` (a test marks its own processes so, e.g. every process
/// of a lab run it started); 0 if none. Only the test's own: other tests may run the same program
/// with the same arguments at the same time.
int pid_with(const std::string& needle, const std::string& tag = "");

/// The path of a program built next to the tests (CPM_BIN_DIR, defined for the support library only).
std::string built_program(const std::string& name);

}  // namespace cpm_test
