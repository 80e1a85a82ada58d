#include <cpm_test/Isolation.hpp>

#include <atomic>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <set>
#include <cstdlib>
#include <stdexcept>
#include <string>

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

namespace cpm_test {
namespace {

// Every /dev/shm path some running process has open or mapped.
std::set<std::string> shm_paths_in_use()
{
    std::set<std::string> used;
    std::error_code ec;
    for (const auto& proc : std::filesystem::directory_iterator("/proc", ec)) {
        const std::string pid = proc.path().filename();
        if (pid.empty() || !std::isdigit(static_cast<unsigned char>(pid[0]))) continue;
        for (const auto& fd : std::filesystem::directory_iterator(proc.path() / "fd", ec)) {
            auto target = std::filesystem::read_symlink(fd.path(), ec);
            if (!ec && target.string().rfind("/dev/shm/", 0) == 0) used.insert(target.string());
        }
        std::ifstream maps(proc.path() / "maps");
        for (std::string line; std::getline(maps, line);) {
            const auto at = line.find("/dev/shm/");
            if (at != std::string::npos) used.insert(line.substr(at));
        }
    }
    return used;
}

// A process killed with SIGKILL (some tests do that on purpose) can leave a Fast DDS
// shared-memory port of its domain behind with its mutex locked; a participant that later
// picks that port waits forever. No other test holds this domain now, so every port file of
// it that no process uses is such a leftover.
void remove_stale_shared_memory(int domain)
{
    const int first_port = 7400 + 250 * domain, last_port = first_port + 249;
    const auto used = shm_paths_in_use();
    std::error_code ec;
    for (const auto& entry : std::filesystem::directory_iterator("/dev/shm", ec)) {
        const std::string name = entry.path().filename();
        const auto at = name.find("fastrtps_port");
        if (at != 0 && name.rfind("sem.fastrtps_port", 0) != 0) continue;
        const int port = std::atoi(name.c_str() + name.find("port") + 4);
        if (port < first_port || port > last_port || used.count(entry.path().string())) continue;
        std::filesystem::remove(entry.path(), ec);
    }
}

}  // namespace

namespace {
/// A domain id no other test process holds, locked for the life of this process.
int claim_free_domain()
{
    const std::string dir = "/tmp/cpm_test_domains";
    ::mkdir(dir.c_str(), 0777);
    const int start = static_cast<int>(::getpid() % 232);
    for (int i = 0; i < 232; ++i) {
        const int candidate = 1 + (start + i) % 232;
        const std::string path = dir + "/" + std::to_string(candidate) + ".lock";
        const int fd = ::open(path.c_str(), O_CREAT | O_RDWR | O_CLOEXEC, 0666);
        if (fd < 0) continue;
        if (::flock(fd, LOCK_EX | LOCK_NB) == 0) {
            // Kept open (and locked) for the life of the process.
            remove_stale_shared_memory(candidate);
            return candidate;
        }
        ::close(fd);
    }
    throw std::runtime_error("no free DDS domain id in 1..232 for this test process");
}
}  // namespace

int test_domain_id()
{
    static const int id = [] {
        const int candidate = claim_free_domain();
        ::setenv("CPM_DOMAIN_ID", std::to_string(candidate).c_str(), 1);
        return candidate;
    }();
    return id;
}

int extra_test_domain_id()
{
    (void)test_domain_id();  // the process's own first
    return claim_free_domain();
}

std::string unique_topic(const std::string& base)
{
    static std::atomic<int> counter{0};
    return base + "_" + std::to_string(::getpid()) + "_" + std::to_string(counter++);
}

bool wait_until(const std::function<bool()>& condition, std::chrono::milliseconds timeout,
                std::chrono::milliseconds poll)
{
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (!condition()) {
        if (std::chrono::steady_clock::now() >= deadline) return condition();
        std::this_thread::sleep_for(poll);
    }
    return true;
}

bool holds_for(const std::function<bool()>& condition, std::chrono::milliseconds window, std::chrono::milliseconds poll)
{
    const auto deadline = std::chrono::steady_clock::now() + window;
    while (std::chrono::steady_clock::now() < deadline) {
        if (!condition()) return false;
        std::this_thread::sleep_for(poll);
    }
    return condition();
}

namespace {

/// A TCP socket bound to a port of 127.0.0.1 the system chose; its port.
int bound_tcp_socket(int& port)
{
    const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
    socklen_t len = sizeof a;
    ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
    port = ntohs(a.sin_port);
    return fd;
}

}  // namespace

int free_tcp_port()
{
    int port = 0;
    ::close(bound_tcp_socket(port));
    return port;
}

HeldTcpPort::HeldTcpPort()
{
    fd_ = bound_tcp_socket(port_);
    if (::listen(fd_, 1) != 0) throw std::runtime_error("HeldTcpPort: cannot listen on 127.0.0.1:" + std::to_string(port_));
}

HeldTcpPort::~HeldTcpPort() { ::close(fd_); }

}  // namespace cpm_test
