#pragma once
// Another computer of the lab, reached with OpenSSH (no agent of cpm's own): the ssh command
// that runs a program there tied to the connection, the other side of that tie (`cpm host run`),
// and the host's clock measured against this one's.
//
//   cpm::RemoteHost car{.name = "car5", .ssh = "pi@192.168.1.21", .cpm_prefix = "/opt/cpm"};
//   auto argv = cpm::remote_command(car, {"/opt/cpm/bin/fsm_node", "--vehicle_id", "5"});
//   // ssh -o BatchMode=yes ... pi@192.168.1.21 -- '/opt/cpm/bin/cpm' host run -- '/opt/cpm/bin/fsm_node' ...
//
// A program started so runs in a process group of its own on that host; it is stopped (SIGINT,
// then SIGTERM and SIGKILL after its grace) when its ssh's input closes: when the supervisor
// closes it, when the supervisor dies, or when the connection is lost.
#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

namespace cpm {

struct RemoteHost
{
    std::string name;                      ///< the lab's name for it ("car5"), for messages; "" is this host
    std::string ssh;                       ///< ssh's destination: "pi@192.168.1.21", or a Host of an ssh config
    std::vector<std::string> ssh_options;  ///< more options for ssh, e.g. {"-F", "lab_ssh_config"}
    std::string cpm_prefix;                ///< where cpm is installed there: its programs are in PREFIX/bin
    /// A private folder (mode 0700) where ssh keeps one connection to the host that every
    /// command shares (OpenSSH's ControlMaster): one key exchange per host instead of one per
    /// command. "" each command connects on its own. End it with close_shared_connection().
    std::string shared_connection_dir;
    bool is_local() const { return name.empty(); }
    /// PREFIX/bin/program.
    std::string program(const std::string& name) const;
};

/// How long `cpm host run` goes on without a word from the run before it stops what it runs:
/// the run writes a line to each remote process's input every second (ProcessGroup), so that a
/// host cut off from it stops the run's processes by itself instead of leaving them running.
inline constexpr std::chrono::milliseconds kRemoteLease{10'000};
/// What `cpm host run` spends at most past a process's grace: SIGTERM, then SIGKILL after
/// kRemoteTermWait; then what the process left in its group gets kRemoteGroupEndWait.
inline constexpr std::chrono::milliseconds kRemoteTermWait{2000}, kRemoteGroupEndWait{1000};

/// The argv that runs `remote_argv` (argv[0]: a path on that host) there, non-interactively
/// (BatchMode: a host that asks for a password fails at once), tied to the connection through
/// `cpm host run` with the given grace and kRemoteLease.
std::vector<std::string> remote_command(const RemoteHost& host, const std::vector<std::string>& remote_argv,
                                        std::chrono::milliseconds grace = std::chrono::seconds(5));
/// The argv that runs a plain command there and returns (checks: `cpm --version`, `test -x`).
std::vector<std::string> ssh_command(const RemoteHost& host, const std::vector<std::string>& remote_argv);
/// Ends the connection the host's commands share (ssh -O exit), when there is one; quietly.
void close_shared_connection(const RemoteHost& host);
/// `text` quoted for the remote shell: 'it'\''s'.
std::string shell_quote(const std::string& text);

/// The remote side of remote_command (`cpm host run`): starts `argv` in a process group of its
/// own with this process's stdout and stderr, and supervises it until it ends, stdin reaches its
/// end, or (`lease` > 0) nothing came on stdin for `lease` (the run's host is gone: said on
/// stderr); then SIGINT, SIGTERM and SIGKILL, `grace` apart. Returns its exit code, or 128 + the
/// signal that ended it (as a shell does). Throws cpm::Error when it cannot be started.
int run_until_input_ends(const std::vector<std::string>& argv, std::chrono::milliseconds grace,
                         std::chrono::milliseconds lease = std::chrono::milliseconds(0));

/// Why a port cannot be taken on this host ("tcp" or "udp", on every address, as a server
/// would): strerror of the bind ("Address already in use"); "" when it is free.
std::string port_taken(const std::string& protocol, int port);

/// The remote side of measure_clock (`cpm host clock`): answers each line of stdin with this
/// host's CLOCK_REALTIME in nanoseconds, until stdin ends.
void answer_clock_queries();

/// A host's clock against this one's: its time minus ours, from the round trip with the least
/// delay among `rounds` over one ssh connection; the true offset lies within ±rtt/2 of it.
struct ClockOffset
{
    int64_t offset_ns = 0;
    int64_t rtt_ns = 0;
};
/// Throws cpm::Error naming the host and what ssh said when it cannot be reached.
ClockOffset measure_clock(const RemoteHost& host, int rounds = 20);

}  // namespace cpm
