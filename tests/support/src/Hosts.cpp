#include <cpm_test/Hosts.hpp>

#include <cpm_test/Isolation.hpp>
#include <cpm_test/Process.hpp>

#include <dirent.h>
#include <fcntl.h>
#include <sched.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace cpm_test {

namespace {

int shell(const std::string& command) { return std::system((command + " >/dev/null 2>&1").c_str()); }

}  // namespace

void remove_stale_namespaces() { shell(CPM_NETNS_CLEAN_SCRIPT); }

NamespaceHosts::NamespaceHosts(std::vector<std::string> names) : names_(std::move(names))
{
    remove_stale_namespaces();
    const std::string tag = std::to_string(::getpid());
    subnet_ = "10.231." + std::to_string(::getpid() % 250 + 1);
    switch_ns_ = "cpmsw" + tag;
    for (size_t i = 0; i < names_.size(); ++i) {
        namespaces_.push_back("cpmh" + tag + "_" + std::to_string(i));
        links_.push_back("cpmv" + tag + "_" + std::to_string(i));
    }
    char tmpl[] = "/tmp/cpm_hosts_XXXXXX";
    dir_ = ::mkdtemp(tmpl) ? tmpl : "";
    if (::geteuid() != 0) why_not_ = "making network namespaces needs root (ip netns)";
    else if (::access("/usr/sbin/sshd", X_OK) != 0) why_not_ = "Debian's openssh-server is not installed (/usr/sbin/sshd)";
    else if (dir_.empty()) why_not_ = "cannot make a folder in /tmp";
    else if (!make()) return;
    for (size_t i = 0; why_not_.empty() && i < names_.size(); ++i) {
        if (!start_sshd(i)) why_not_ = "sshd did not start in the namespace of " + names_[i] + ": " + file_text(dir_ + "/sshd_" + std::to_string(i) + ".log");
    }
}

bool NamespaceHosts::make()
{
    auto fail = [&](const std::string& what) {
        why_not_ = what;
        return false;
    };
    if (shell("ip netns add " + switch_ns_) != 0) return fail("ip netns add failed");
    const std::string sw = "ip netns exec " + switch_ns_ + " ";
    if (shell(sw + "ip link add br0 type bridge") != 0 || shell(sw + "ip link set br0 up") != 0) return fail("no bridge in the switch namespace");
    for (size_t i = 0; i < names_.size(); ++i) {
        const std::string in = "ip netns exec " + namespaces_[i] + " ";
        const std::string peer = "cpms" + std::to_string(::getpid()) + "_" + std::to_string(i);
        const bool ok = shell("ip netns add " + namespaces_[i]) == 0 &&
                        shell("ip link add " + links_[i] + " netns " + namespaces_[i] + " type veth peer name " + peer + " netns " + switch_ns_) == 0 &&
                        shell(sw + "ip link set " + peer + " master br0") == 0 && shell(sw + "ip link set " + peer + " up") == 0 &&
                        shell(in + "ip link set lo up") == 0 && shell(in + "ip addr add " + address(i) + "/24 dev " + links_[i]) == 0 &&
                        shell(in + "ip link set " + links_[i] + " up") == 0;
        if (!ok) return fail("could not make the namespace of " + names_[i] + " with its veth pair");
    }
    // Keys: the hosts' (one for all: they are one machine) and the client's; an ssh config by name.
    if (shell("ssh-keygen -q -t ed25519 -N '' -f " + dir_ + "/host_key") != 0 || shell("ssh-keygen -q -t ed25519 -N '' -f " + dir_ + "/id") != 0)
        return fail("ssh-keygen failed");
    std::filesystem::copy_file(dir_ + "/id.pub", dir_ + "/authorized_keys");
    const std::string host_key = file_text(dir_ + "/host_key.pub");
    std::ofstream known(dir_ + "/known_hosts");
    std::ofstream config(dir_ + "/ssh_config");
    for (size_t i = 0; i < names_.size(); ++i) {
        known << address(i) << " " << host_key;
        config << "Host " << names_[i] << " " << address(i) << "\n  HostName " << address(i) << "\n  User root\n";
    }
    config << "Host *\n  IdentityFile " << dir_ << "/id\n  IdentitiesOnly yes\n  UserKnownHostsFile " << dir_
           << "/known_hosts\n  StrictHostKeyChecking yes\n  GlobalKnownHostsFile /dev/null\n";
    ssh_config_ = dir_ + "/ssh_config";
    ::mkdir("/run/sshd", 0755);  // sshd's privilege separation folder
    return true;
}

bool NamespaceHosts::start_sshd(size_t i, const std::string& set_env)
{
    const std::string log = dir_ + "/sshd_" + std::to_string(i) + ".log";
    const pid_t pid = ::fork();
    if (pid == 0) {
        const std::string ns = namespaces_[i];
        const std::string listen = "ListenAddress=" + address(i);
        const std::string keys = "AuthorizedKeysFile=" + dir_ + "/authorized_keys";
        const std::string hostkey = dir_ + "/host_key";
        const std::string pidfile = "PidFile=" + dir_ + "/sshd_" + std::to_string(i) + ".pid";
        ::setpgid(0, 0);
        const std::string env = "SetEnv " + (set_env.empty() ? std::string("CPM_NAMESPACE_HOST=1") : set_env);
        ::execl("/usr/sbin/ip", "ip", "netns", "exec", ns.c_str(), "/usr/sbin/sshd", "-D", "-e", "-f", "/dev/null", "-h", hostkey.c_str(), "-o",
                listen.c_str(), "-o", keys.c_str(), "-o", "PermitRootLogin=prohibit-password", "-o", "StrictModes=no", "-o", "UsePAM=no", "-o",
                pidfile.c_str(), "-o", "AcceptEnv=CPM_*", "-o", env.c_str(), "-E", log.c_str(), nullptr);
        ::_exit(127);
    }
    if (i < sshd_pids_.size()) sshd_pids_[i] = pid;
    else sshd_pids_.push_back(pid);
    // Reached from the first host over the bridge: its sshd is up and the links are.
    return wait_until([&] { return shell("ip netns exec " + namespaces_[0] + " ssh -F " + dir_ + "/ssh_config " + names_[i] + " true") == 0; },
                      std::chrono::seconds(15), std::chrono::milliseconds(100));
}

NamespaceHosts::~NamespaceHosts()
{
    for (size_t i = 0; i < sshd_pids_.size(); ++i) stop_sshd(i);
    // Whatever still runs in a host's namespace goes with it.
    for (size_t i = 0; i < namespaces_.size(); ++i) {
        for (int pid : pids(i)) ::kill(pid, SIGKILL);
        shell("ip netns del " + namespaces_[i]);
    }
    shell("ip netns del " + switch_ns_);
    if (!dir_.empty()) std::filesystem::remove_all(dir_);
}

std::string NamespaceHosts::address(size_t host) const { return subnet_ + "." + std::to_string(host + 1); }

cpm::RemoteHost NamespaceHosts::remote(size_t host, const std::string& cpm_prefix) const
{
    return {.name = names_[host], .ssh = names_[host], .ssh_options = {"-F", ssh_config_}, .cpm_prefix = cpm_prefix};
}

std::vector<std::string> NamespaceHosts::in(size_t host, std::vector<std::string> argv) const
{
    argv.insert(argv.begin(), {"/usr/sbin/ip", "netns", "exec", namespaces_[host]});
    return argv;
}

std::vector<int> NamespaceHosts::pids(size_t host) const
{
    std::vector<int> out;
    FILE* p = ::popen(("ip netns pids " + namespaces_[host] + " 2>/dev/null").c_str(), "r");
    if (!p) return out;
    int pid = 0;
    while (std::fscanf(p, "%d", &pid) == 1) {
        if (host < sshd_pids_.size() && pid == sshd_pids_[host]) continue;
        // sshd's listener (the one ip netns exec became) is ours; its sessions' processes are not.
        const std::string cmd = file_text("/proc/" + std::to_string(pid) + "/cmdline");
        if (cmd.rfind("/usr/sbin/sshd", 0) == 0 && cmd.find("-D") != std::string::npos) continue;
        out.push_back(pid);
    }
    ::pclose(p);
    return out;
}

bool NamespaceHosts::cut(size_t host) const { return shell("ip netns exec " + namespaces_[host] + " ip link set " + links_[host] + " down") == 0; }
bool NamespaceHosts::heal(size_t host) const { return shell("ip netns exec " + namespaces_[host] + " ip link set " + links_[host] + " up") == 0; }

uint64_t NamespaceHosts::received_bytes(size_t host) const
{
    // ip netns exec mounts the namespace's own /sys, where the link's counters are.
    FILE* p = ::popen(("ip netns exec " + namespaces_[host] + " cat /sys/class/net/" + links_[host] + "/statistics/rx_bytes 2>/dev/null").c_str(), "r");
    if (!p) return 0;
    unsigned long long bytes = 0;
    if (std::fscanf(p, "%llu", &bytes) != 1) bytes = 0;
    ::pclose(p);
    return bytes;
}

void NamespaceHosts::stop_sshd(size_t host)
{
    if (host >= sshd_pids_.size() || sshd_pids_[host] <= 0) return;
    ::kill(sshd_pids_[host], SIGTERM);
    ::waitpid(sshd_pids_[host], nullptr, 0);
    sshd_pids_[host] = -1;
}

std::string cpm_prefix() { return std::filesystem::path(built_program("cpm")).parent_path().parent_path().string(); }

std::string command_line(int pid)
{
    std::string s = file_text("/proc/" + std::to_string(pid) + "/cmdline");
    for (char& c : s) c = c == '\0' ? ' ' : c;
    return s;
}

bool NamespaceHosts::offset_clock(size_t host, const std::string& offset)
{
    const char* lib = "/usr/lib/x86_64-linux-gnu/faketime/libfaketime.so.1";
    if (::access(lib, R_OK) != 0) return false;
    stop_sshd(host);
    return start_sshd(host, std::string("LD_PRELOAD=") + lib + " FAKETIME=" + offset);
}

unsigned long NamespaceHosts::netns_inode(size_t host) const
{
    struct stat st{};
    return ::stat(("/var/run/netns/" + namespaces_[host]).c_str(), &st) == 0 ? st.st_ino : 0;
}

NamespaceHosts::Inside::Inside(const NamespaceHosts& hosts, size_t host) : before_(::open("/proc/self/ns/net", O_RDONLY | O_CLOEXEC))
{
    const int fd = ::open(("/var/run/netns/" + hosts.netns(host)).c_str(), O_RDONLY | O_CLOEXEC);
    if (fd >= 0) {
        (void)::setns(fd, CLONE_NEWNET);
        ::close(fd);
    }
}

NamespaceHosts::Inside::~Inside()
{
    if (before_ >= 0) {
        (void)::setns(before_, CLONE_NEWNET);
        ::close(before_);
    }
}

}  // namespace cpm_test
