#include <cpm/RemoteHost.hpp>

#include <cpm/ChildProcess.hpp>
#include <cpm/Error.hpp>

#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstring>
#include <cstdio>
#include <ctime>
#include <iostream>
#include <limits>
#include <optional>

namespace cpm {

namespace {

int64_t realtime_ns()
{
    timespec ts{};
    ::clock_gettime(CLOCK_REALTIME, &ts);
    return int64_t(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

/// The ssh program itself, as a path (ChildProcess runs paths, not names on PATH).
std::string ssh_program()
{
    for (const char* p : {"/usr/bin/ssh", "/usr/local/bin/ssh", "/bin/ssh"}) {
        if (::access(p, X_OK) == 0) return p;
    }
    throw Error("ssh is not installed (the Debian package openssh-client); a lab across hosts needs it");
}

/// The code a shell reports for an end: the exit code, or 128 + the signal.
int shell_code(const ExitStatus& end) { return end.signal != 0 ? 128 + end.signal : end.code; }

}  // namespace

std::string RemoteHost::program(const std::string& program_name) const { return cpm_prefix + "/bin/" + program_name; }

std::string shell_quote(const std::string& text)
{
    std::string out = "'";
    for (char c : text) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return out + "'";
}

namespace {

/// ssh and the options every command to the host takes, up to its destination.
std::vector<std::string> ssh_to(const RemoteHost& host)
{
    // Never a prompt (BatchMode), a lost host noticed within about 3 s (ServerAlive*: the shared
    // connection's, which ends every command on it), a new host's key not taken on trust
    // silently (the lab's hosts are in known_hosts: StrictHostKeyChecking stays as configured).
    std::vector<std::string> argv{ssh_program(), "-o", "BatchMode=yes", "-o", "ConnectTimeout=5", "-o", "ServerAliveInterval=1",
                                  "-o", "ServerAliveCountMax=3", "-o", "LogLevel=ERROR"};
    if (!host.shared_connection_dir.empty()) {
        // The first command opens it in the background; it outlives a gap between commands
        // (ControlPersist) and is ended by close_shared_connection.
        argv.insert(argv.end(), {"-o", "ControlMaster=auto", "-o", "ControlPath=" + host.shared_connection_dir + "/%C", "-o", "ControlPersist=60"});
    }
    argv.insert(argv.end(), host.ssh_options.begin(), host.ssh_options.end());
    return argv;
}

}  // namespace

void close_shared_connection(const RemoteHost& host)
{
    if (host.is_local() || host.shared_connection_dir.empty()) return;
    auto argv = ssh_to(host);
    argv.insert(argv.end(), {"-O", "exit", host.ssh});
    try {
        ChildProcess ssh({.argv = argv, .stdout_path = "/dev/null", .stderr_path = "/dev/null"});
        (void)ssh.wait(std::chrono::seconds(5));
    } catch (const Error&) {
    }
}

std::vector<std::string> ssh_command(const RemoteHost& host, const std::vector<std::string>& remote_argv)
{
    std::vector<std::string> argv = ssh_to(host);
    argv.push_back(host.ssh);
    argv.push_back("--");
    std::string command;
    for (const auto& a : remote_argv) command += (command.empty() ? "" : " ") + shell_quote(a);
    argv.push_back(command);
    return argv;
}

std::vector<std::string> remote_command(const RemoteHost& host, const std::vector<std::string>& remote_argv, std::chrono::milliseconds grace)
{
    std::vector<std::string> wrapped{host.program("cpm"), "host", "run", "--grace", std::to_string(grace.count()) + "ms",
                                     "--lease", std::to_string(kRemoteLease.count()) + "ms", "--"};
    wrapped.insert(wrapped.end(), remote_argv.begin(), remote_argv.end());
    return ssh_command(host, wrapped);
}

namespace {

/// Ends what is left of a process group whose leader has ended (what it started in the
/// background, which would else keep the connection open): SIGTERM (and SIGCONT for the frozen
/// ones), then SIGKILL.
int with_group_ended(int group, int code)
{
    if (::kill(-group, SIGTERM) == 0) {
        ::kill(-group, SIGCONT);
        for (auto waited = std::chrono::milliseconds(0); waited < kRemoteGroupEndWait && ::kill(-group, 0) == 0;
             waited += std::chrono::milliseconds(50))
            ::usleep(50'000);
        ::kill(-group, SIGKILL);
    }
    return code;
}

}  // namespace

int run_until_input_ends(const std::vector<std::string>& argv, std::chrono::milliseconds grace, std::chrono::milliseconds lease)
{
    ChildProcess child({.argv = argv, .own_process_group = true, .die_with_parent = true});
    const int group = child.pid();
    pollfd in{STDIN_FILENO, POLLIN, 0};
    bool input_open = true;
    auto last_word = std::chrono::steady_clock::now();
    for (;;) {
        if (auto end = child.ended()) return with_group_ended(group, shell_code(*end));
        if (!input_open) break;
        if (lease.count() > 0 && std::chrono::steady_clock::now() - last_word > lease) {
            std::fprintf(stderr, "cpm host run: no word from the run for %lld ms (its host cut off?): stopping %s\n",
                         static_cast<long long>(lease.count()), argv.front().c_str());
            break;
        }
        const int n = ::poll(&in, 1, 100);
        if (n > 0) {
            char buf[256];
            const ssize_t got = ::read(STDIN_FILENO, buf, sizeof buf);
            if (got == 0 || (got < 0 && errno != EINTR && errno != EAGAIN)) input_open = false;
            else if (got > 0) last_word = std::chrono::steady_clock::now();
        }
    }
    // The supervisor closed our input, died, or lost the connection: stop it, as a local one is stopped.
    child.ask_to_stop(SIGINT);
    if (auto end = child.wait(grace)) return with_group_ended(group, shell_code(*end));
    return with_group_ended(group, shell_code(child.stop(kRemoteTermWait)));
}

std::string port_taken(const std::string& protocol, int port)
{
    const int fd = ::socket(AF_INET, (protocol == "tcp" ? SOCK_STREAM : SOCK_DGRAM) | SOCK_CLOEXEC, 0);
    if (fd < 0) return std::strerror(errno);
    if (protocol == "tcp") {  // as a server does: a connection of an earlier one in TIME_WAIT does not count
        const int one = 1;
        ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    }
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_ANY);
    a.sin_port = htons(uint16_t(port));
    const bool bound = ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
    const std::string why = bound ? "" : std::strerror(errno);
    ::close(fd);
    return why;
}

void answer_clock_queries()
{
    for (std::string line; std::getline(std::cin, line);) {
        std::printf("%lld\n", static_cast<long long>(realtime_ns()));
        std::fflush(stdout);
    }
}

ClockOffset measure_clock(const RemoteHost& host, int rounds)
{
    ChildProcess ssh({.argv = ssh_command(host, {host.program("cpm"), "host", "clock"}), .capture_stdout = true, .pipe_stdin = true});
    std::optional<ClockOffset> best;
    for (int i = 0; i < rounds; ++i) {
        const int64_t sent = realtime_ns();
        if (!ssh.write_stdin("?\n")) break;
        const auto answer = ssh.read_line();
        const int64_t back = realtime_ns();
        if (!answer) break;
        long long theirs = 0;
        if (std::sscanf(answer->c_str(), "%lld", &theirs) != 1) {
            throw Error("host " + host.name + " (" + host.ssh + "): its clock answered '" + *answer + "', not a time (is cpm there the same version?)");
        }
        const ClockOffset sample{theirs - (sent + back) / 2, back - sent};
        if (!best || sample.rtt_ns < best->rtt_ns) best = sample;
    }
    ssh.close_stdin();
    const auto end = ssh.wait(std::chrono::seconds(5));
    if (!best) {
        throw Error("host " + host.name + " (" + host.ssh + "): cannot measure its clock: ssh " +
                    (end ? end->describe() : std::string("did not answer")) + " (is the host reachable, its key in known_hosts, cpm installed in " +
                    host.cpm_prefix + "?)");
    }
    return *best;
}

}  // namespace cpm
