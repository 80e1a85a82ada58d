#include <cpm_test/Isolation.hpp>

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <string>

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

namespace cpm_test {

int test_domain_id()
{
    static const int id = [] {
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
                ::setenv("CPM_DOMAIN_ID", std::to_string(candidate).c_str(), 1);
                return candidate;
            }
            ::close(fd);
        }
        throw std::runtime_error("no free DDS domain id in 1..232 for this test process");
    }();
    return id;
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

}  // namespace cpm_test
