#include <cpm/ChildProcess.hpp>

#include <cpm/Error.hpp>

#include <cerrno>
#include <climits>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <thread>

#include <fcntl.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

extern char** environ;

namespace cpm {

namespace {

ExitStatus status_of(int raw)
{
    ExitStatus s;
    if (WIFEXITED(raw)) s.code = WEXITSTATUS(raw);
    if (WIFSIGNALED(raw)) s.signal = WTERMSIG(raw);
    return s;
}

int open_output(const std::string& path, bool append)
{
    const int fd = ::open(path.c_str(), O_CREAT | (append ? O_APPEND : O_TRUNC) | O_WRONLY | O_CLOEXEC, 0644);
    if (fd < 0) throw Error("cannot write " + path + ": " + std::strerror(errno));
    return fd;
}

}  // namespace

std::string ExitStatus::describe() const
{
    if (signal != 0) {
        const char* name = sigabbrev_np(signal);
        return "killed by " + (name ? "SIG" + std::string(name) : "signal " + std::to_string(signal));
    }
    return "exited with code " + std::to_string(code);
}

ChildProcess::ChildProcess(ProcessOptions o) : program_(o.argv.empty() ? "" : o.argv[0]), group_(o.own_process_group)
{
    if (o.argv.empty()) throw Error("ChildProcess: no program given");
    if (::access(program_.c_str(), X_OK) != 0) throw Error("cannot run " + program_ + ": " + std::strerror(errno));
    // Everything the child needs is made before fork(): between fork and exec only
    // async-signal-safe calls (this process may have many threads).
    std::vector<std::string> envs;
    for (char** e = environ; *e; ++e) envs.emplace_back(*e);
    envs.insert(envs.end(), o.env.begin(), o.env.end());
    std::vector<char*> args, envp;
    for (auto& a : o.argv) args.push_back(a.data());
    args.push_back(nullptr);
    for (auto& e : envs) envp.push_back(e.data());
    envp.push_back(nullptr);
    const int out_file = o.stdout_path.empty() ? -1 : open_output(o.stdout_path, o.append_output);
    int err_file = -1;
    try {
        // One file for both: one open file (one offset), so neither overwrites the other.
        if (!o.stderr_path.empty() && o.stderr_path == o.stdout_path) err_file = ::fcntl(out_file, F_DUPFD_CLOEXEC, 0);
        else err_file = o.stderr_path.empty() ? -1 : open_output(o.stderr_path, o.append_output);
    } catch (...) {
        if (out_file >= 0) ::close(out_file);
        throw;
    }
    int pipe_fds[2] = {-1, -1};
    if (o.capture_stdout && ::pipe2(pipe_fds, O_CLOEXEC) != 0) throw Error("cannot make a pipe for " + program_);
    int in_fds[2] = {-1, -1};
    if (o.pipe_stdin && ::pipe2(in_fds, O_CLOEXEC) != 0) throw Error("cannot make a pipe for " + program_ + "'s input");
    const pid_t parent = ::getpid();

    pid_ = ::fork();
    if (pid_ < 0) throw Error("cannot start " + program_ + ": " + std::strerror(errno));
    if (pid_ == 0) {
        if (o.die_with_parent) {
            ::prctl(PR_SET_PDEATHSIG, SIGTERM);
            if (::getppid() != parent) ::_exit(127);  // the parent died before the line above
        }
        if (o.own_process_group) ::setpgid(0, 0);
        if (in_fds[0] >= 0) ::dup2(in_fds[0], STDIN_FILENO);
        if (pipe_fds[1] >= 0) ::dup2(pipe_fds[1], STDOUT_FILENO);
        else if (out_file >= 0) ::dup2(out_file, STDOUT_FILENO);
        if (err_file >= 0) ::dup2(err_file, STDERR_FILENO);
        // Nothing of ours leaks into the child (Fast DDS's shared-memory lock files included,
        // which would make its ports look held by the wrong process).
        ::close_range(3, ~0u, 0);
        ::execve(args[0], args.data(), envp.data());
        const char msg[] = "cannot exec the program\n";
        (void)!::write(STDERR_FILENO, msg, sizeof msg - 1);
        ::_exit(127);
    }
    if (out_file >= 0) ::close(out_file);
    if (err_file >= 0) ::close(err_file);
    if (pipe_fds[1] >= 0) ::close(pipe_fds[1]);
    if (in_fds[0] >= 0) ::close(in_fds[0]);
    out_fd_ = pipe_fds[0];
    in_fd_ = in_fds[1];
}

ChildProcess::~ChildProcess()
{
    if (pid_ > 0 && !end_) stop();
    release();
}

ChildProcess::ChildProcess(ChildProcess&& other) noexcept
    : program_(std::move(other.program_)), pid_(other.pid_), out_fd_(other.out_fd_), in_fd_(other.in_fd_), group_(other.group_), end_(other.end_)
{
    other.pid_ = -1;
    other.out_fd_ = -1;
    other.in_fd_ = -1;
}

ChildProcess& ChildProcess::operator=(ChildProcess&& other) noexcept
{
    if (this != &other) {
        if (pid_ > 0 && !end_) stop();
        release();
        program_ = std::move(other.program_);
        pid_ = other.pid_;
        out_fd_ = other.out_fd_;
        in_fd_ = other.in_fd_;
        group_ = other.group_;
        end_ = other.end_;
        other.pid_ = -1;
        other.out_fd_ = -1;
        other.in_fd_ = -1;
    }
    return *this;
}

void ChildProcess::release()
{
    if (out_fd_ >= 0) ::close(out_fd_);
    out_fd_ = -1;
    close_stdin();
}

std::optional<ExitStatus> ChildProcess::ended()
{
    if (end_ || pid_ <= 0) return end_;
    int raw = 0;
    if (::waitpid(pid_, &raw, WNOHANG) == pid_) end_ = status_of(raw);
    return end_;
}

bool ChildProcess::running() { return pid_ > 0 && !ended(); }

std::optional<ExitStatus> ChildProcess::wait(std::chrono::milliseconds timeout)
{
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (!ended()) {
        if (pid_ <= 0 || std::chrono::steady_clock::now() >= deadline) return std::nullopt;
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    return end_;
}

void ChildProcess::signal(int sig)
{
    if (pid_ <= 0 || end_) return;
    ::kill(group_ ? -pid_ : pid_, sig);
}

void ChildProcess::ask_to_stop(int sig)
{
    signal(sig);
    signal(SIGCONT);
}

ExitStatus ChildProcess::stop(std::chrono::milliseconds grace)
{
    if (pid_ <= 0) return {};
    ask_to_stop(SIGTERM);
    if (auto end = wait(grace)) return *end;
    signal(SIGKILL);
    int raw = 0;
    if (::waitpid(pid_, &raw, 0) == pid_) end_ = status_of(raw);
    return end_.value_or(ExitStatus{});
}

std::optional<std::string> ChildProcess::read_line()
{
    if (out_fd_ < 0) return std::nullopt;
    std::string line;
    char c;
    for (;;) {
        const ssize_t n = ::read(out_fd_, &c, 1);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) return line.empty() ? std::nullopt : std::optional(line);
        if (c == '\n') return line;
        line += c;
    }
}

std::string executable_dir()
{
    char path[PATH_MAX];
    const ssize_t n = ::readlink("/proc/self/exe", path, sizeof path - 1);
    if (n <= 0) return ".";
    const std::string exe(path, size_t(n));
    return exe.substr(0, exe.rfind('/'));
}

std::string program_on_path(const std::string& name)
{
    const char* path = std::getenv("PATH");
    std::istringstream dirs(path && *path ? path : "/usr/bin:/bin");
    for (std::string d; std::getline(dirs, d, ':');) {
        const std::string candidate = (d.empty() ? std::string(".") : d) + "/" + name;
        if (::access(candidate.c_str(), X_OK) == 0) return candidate;
    }
    return "";
}

std::string sibling_executable(const std::string& name)
{
    const std::string path = executable_dir() + "/" + name;
    if (::access(path.c_str(), X_OK) != 0) {
        throw Error(name + " is not beside this program (" + path + ": " + std::strerror(errno) +
                    "); cpm's programs are installed together");
    }
    return path;
}

}  // namespace cpm

namespace cpm {

bool ChildProcess::write_stdin(const std::string& text)
{
    // A child that no longer reads would raise SIGPIPE, which ends a process by default: it is
    // blocked on this thread for the write, and a pending one taken (the write says EPIPE).
    sigset_t pipe_only, before;
    sigemptyset(&pipe_only);
    sigaddset(&pipe_only, SIGPIPE);
    ::pthread_sigmask(SIG_BLOCK, &pipe_only, &before);
    size_t done = 0;
    bool ok = in_fd_ >= 0;
    while (ok && done < text.size()) {
        const ssize_t n = ::write(in_fd_, text.data() + done, text.size() - done);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) {
            ok = false;
            if (errno == EPIPE) {
                const timespec none{0, 0};
                ::sigtimedwait(&pipe_only, nullptr, &none);
            }
            break;
        }
        done += size_t(n);
    }
    ::pthread_sigmask(SIG_SETMASK, &before, nullptr);
    return ok;
}

void ChildProcess::close_stdin()
{
    if (in_fd_ >= 0) ::close(in_fd_);
    in_fd_ = -1;
}

}  // namespace cpm
