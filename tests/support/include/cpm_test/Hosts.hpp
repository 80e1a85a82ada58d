#pragma once
// Hosts for tests of a lab across computers, made on this machine as root: a network namespace
// per host, joined through a bridge in a namespace of its own by veth pairs (nothing reaches any
// other address), each running Debian's sshd on its own address with keys made here. An ssh
// config (ssh_config()) reaches them by name, non-interactively. Removed by the destructor.
#include <cpm/RemoteHost.hpp>

#include <cstdint>

#include <string>
#include <vector>

namespace cpm_test {

/// Removes the network namespaces of test processes that are gone (killed before their
/// destructor ran: a ctest timeout, a CI job cut off); scripts/netns_clean.sh, which ./lab test
/// also runs at its end. Those of running processes are kept.
void remove_stale_namespaces();

class NamespaceHosts
{
public:
    /// `names`: the hosts ("central", "car_a", ...), addresses 10.<subnet>.<1, 2, ...>. A failure
    /// to make them is in why_not() (the test then skips, saying why, or fails under CI).
    explicit NamespaceHosts(std::vector<std::string> names);
    ~NamespaceHosts();
    NamespaceHosts(const NamespaceHosts&) = delete;
    NamespaceHosts& operator=(const NamespaceHosts&) = delete;

    /// "" when every host is up with its sshd; else what failed.
    const std::string& why_not() const { return why_not_; }
    std::string address(size_t host) const;
    const std::string& netns(size_t host) const { return namespaces_[host]; }
    /// The ssh config file that reaches each host by its name (and its address) as root.
    const std::string& ssh_config() const { return ssh_config_; }
    /// Host `host` as a lab run reaches it, cpm's programs in `cpm_prefix`/bin.
    cpm::RemoteHost remote(size_t host, const std::string& cpm_prefix) const;
    /// argv that runs a program in the host's namespace (not over ssh).
    std::vector<std::string> in(size_t host, std::vector<std::string> argv) const;
    /// The pids of the processes in the host's namespace (sshd's own listener left out).
    std::vector<int> pids(size_t host) const;
    /// Takes the host's link down (a cable pulled) or up again.
    bool cut(size_t host) const;
    bool heal(size_t host) const;
    /// Bytes the host's link has received so far (what crossed the wire to it, not shared memory).
    uint64_t received_bytes(size_t host) const;
    /// Stops the host's sshd (a host where ssh is refused).
    void stop_sshd(size_t host);
    /// Restarts the host's sshd so that what runs there sees its clock `offset` off (libfaketime's
    /// FAKETIME, e.g. "+0.05": 50 ms ahead); false when that cannot be done.
    bool offset_clock(size_t host, const std::string& offset);
    /// The inode of the host's namespace, as /proc/PID/ns/net of a process in it shows.
    unsigned long netns_inode(size_t host) const;

    /// While it lives, this thread (and what it starts) is in the host's namespace.
    class Inside
    {
    public:
        Inside(const NamespaceHosts& hosts, size_t host);
        ~Inside();
        Inside(const Inside&) = delete;
        Inside& operator=(const Inside&) = delete;

    private:
        int before_ = -1;
    };

private:
    bool make();
    bool start_sshd(size_t host, const std::string& set_env = "");

    std::vector<std::string> names_, namespaces_, links_;
    std::string switch_ns_, subnet_, dir_, ssh_config_, why_not_;
    std::vector<int> sshd_pids_;
};

/// Where cpm is "installed" on every namespace host: the build tree (one machine, one disk).
std::string cpm_prefix();
/// A process's command line, its words joined by spaces ("" when it is gone).
std::string command_line(int pid);

}  // namespace cpm_test
