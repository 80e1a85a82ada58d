#pragma once
#include <chrono>
#include <functional>
#include <string>
#include <thread>

namespace cpm_test {

/// A DDS domain id in 1..232 that no other test process on this host holds: claimed with
/// an flock on a file in /tmp/cpm_test_domains and held until the process ends. Also
/// exported as CPM_DOMAIN_ID so child processes and the default participant use it.
int test_domain_id();
/// One more domain id no other test process holds (a new one each call, held as the first): for
/// a second DDS domain of the test's own, such as a controller's.
int extra_test_domain_id();

/// A topic name unique to this process and call ("base_<pid>_<n>").
std::string unique_topic(const std::string& base);

/// A TCP port on 127.0.0.1 nobody listens on now (the system's choice for port 0).
int free_tcp_port();

/// A TCP port on 127.0.0.1 that this object listens on while it lives (something else on a
/// port a test's program wants), in the network namespace of the thread that made it.
class HeldTcpPort
{
public:
    HeldTcpPort();
    ~HeldTcpPort();
    HeldTcpPort(const HeldTcpPort&) = delete;
    HeldTcpPort& operator=(const HeldTcpPort&) = delete;
    int port() const { return port_; }

private:
    int fd_ = -1, port_ = 0;
};

/// Polls `condition` until it is true or `timeout` passes; returns its last value.
bool wait_until(const std::function<bool()>& condition,
                std::chrono::milliseconds timeout = std::chrono::seconds(5),
                std::chrono::milliseconds poll = std::chrono::milliseconds(2));

/// For a negative check: true when `condition` holds for the whole `window` (polled), false as
/// soon as it does not. A broken implementation acts late; a single look would miss it.
bool holds_for(const std::function<bool()>& condition, std::chrono::milliseconds window,
               std::chrono::milliseconds poll = std::chrono::milliseconds(5));

}  // namespace cpm_test
