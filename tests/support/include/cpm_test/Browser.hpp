#pragma once
// A real browser for end-to-end tests of pages: Debian's chromium, headless, driven over the
// DevTools protocol on a pipe (--remote-debugging-pipe: JSON messages ended by NUL on fds 3
// and 4). Every host name is unresolvable to it and its proxy is dead, so nothing it does can
// leave this host; 127.0.0.1 is reachable.
#include <nlohmann/json.hpp>

#include <chrono>
#include <string>
#include <sys/types.h>

namespace cpm_test {

class Browser
{
public:
    /// Starts chromium with its own profile folder, and opens a tab of `width` × `height`.
    /// Throws std::runtime_error when it cannot.
    explicit Browser(int width = 1400, int height = 1000);
    ~Browser();
    Browser(const Browser&) = delete;
    Browser& operator=(const Browser&) = delete;

    /// Loads `url` and waits for its load event.
    void open(const std::string& url);
    /// Evaluates a JavaScript expression in the page (promises awaited), returning its value as
    /// JSON. Throws std::runtime_error with the page's exception text when it throws.
    nlohmann::json eval(const std::string& expression);
    /// Waits until `expression` is truthy in the page (polled every 50 ms); false at timeout.
    bool wait_for(const std::string& expression, std::chrono::milliseconds timeout);
    /// A PNG of what the tab shows, written to `path`.
    void screenshot(const std::string& path);

private:
    nlohmann::json call(const std::string& method, const nlohmann::json& params = nlohmann::json::object(), bool in_tab = true);
    nlohmann::json receive(std::chrono::steady_clock::time_point deadline);

    pid_t pid_ = -1;
    int to_browser_ = -1, from_browser_ = -1;
    int next_id_ = 1;
    std::string session_, buffer_, profile_;
};

}  // namespace cpm_test
