#include <cpm_test/Process.hpp>

#include <cpm_test/Isolation.hpp>

#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <thread>

#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

extern char** environ;

namespace cpm_test {

Process::Process(std::vector<std::string> argv, std::vector<std::string> env)
{
    test_domain_id();  // children inherit CPM_DOMAIN_ID
    char tmpl[] = "/tmp/cpm_test_out_XXXXXX";
    const int out_fd = ::mkstemp(tmpl);
    if (out_fd < 0) throw std::runtime_error("mkstemp failed");
    out_path_ = tmpl;
    char err_tmpl[] = "/tmp/cpm_test_err_XXXXXX";
    const int err_fd = ::mkstemp(err_tmpl);
    if (err_fd < 0) throw std::runtime_error("mkstemp failed");
    err_path_ = err_tmpl;

    std::vector<char*> args;
    for (auto& a : argv) args.push_back(a.data());
    args.push_back(nullptr);
    std::vector<std::string> env_strings;
    for (char** e = environ; *e != nullptr; ++e) env_strings.emplace_back(*e);
    for (auto& e : env) env_strings.push_back(e);
    std::vector<char*> envp;
    for (auto& e : env_strings) envp.push_back(e.data());
    envp.push_back(nullptr);

    pid_ = ::fork();
    if (pid_ < 0) throw std::runtime_error("fork failed");
    if (pid_ == 0) {
        ::dup2(out_fd, STDOUT_FILENO);
        ::dup2(err_fd, STDERR_FILENO);
        ::setpgid(0, 0);
        ::close_range(3, ~0u, 0);  // keep the test's DDS shared-memory lock files out of the child
        ::execve(args[0], args.data(), envp.data());
        std::fprintf(stderr, "cannot start %s: errno %d\n", args[0], errno);
        ::_exit(127);
    }
    ::close(out_fd);
    ::close(err_fd);
}

Process::~Process()
{
    if (!reaped_) {
        kill(SIGTERM);
        if (wait(std::chrono::seconds(3)) == -1 && !reaped_) {
            kill(SIGKILL);
            wait(std::chrono::seconds(3));
        }
    }
    ::unlink(out_path_.c_str());
    ::unlink(err_path_.c_str());
}

int Process::wait(std::chrono::milliseconds timeout)
{
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (!reaped_) {
        const int r = ::waitpid(pid_, &status_, WNOHANG);
        if (r == pid_) {
            reaped_ = true;
            break;
        }
        if (std::chrono::steady_clock::now() >= deadline) return -1;
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    return WIFEXITED(status_) ? WEXITSTATUS(status_) : -1;
}

namespace {

std::string file_text(const std::string& path)
{
    std::ifstream in(path);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

}  // namespace

std::string Process::output() const { return file_text(out_path_); }

std::string Process::errors() const { return file_text(err_path_); }

void Process::kill(int signal)
{
    if (!reaped_ && pid_ > 0) ::kill(-pid_, signal);  // its whole process group: wrappers spawn children
}

std::string built_program(const std::string& name) { return std::string(CPM_BIN_DIR) + "/" + name; }

}  // namespace cpm_test
