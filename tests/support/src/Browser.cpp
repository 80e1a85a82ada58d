#include <cpm_test/Browser.hpp>

#include <cpm/base64.hpp>

#include <csignal>
#include <cstdlib>
#include <fcntl.h>
#include <filesystem>
#include <fstream>
#include <poll.h>
#include <stdexcept>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>
#include <vector>

namespace cpm_test {
namespace {

using Clock = std::chrono::steady_clock;

}  // namespace

Browser::Browser(int width, int height)
{
    char tmpl[] = "/tmp/cpm_browser_XXXXXX";
    if (!::mkdtemp(tmpl)) throw std::runtime_error("Browser: cannot make a profile folder");
    profile_ = tmpl;
    int in[2], out[2];
    if (::pipe2(in, O_CLOEXEC) != 0 || ::pipe2(out, O_CLOEXEC) != 0) throw std::runtime_error("Browser: pipe failed");
    std::vector<std::string> args{"/usr/bin/chromium", "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                                  "--disable-default-apps", "--disable-extensions", "--disable-dev-shm-usage",
                                  "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1", "--proxy-server=127.0.0.1:9",
                                  "--proxy-bypass-list=127.0.0.1", "--remote-debugging-pipe", "--user-data-dir=" + profile_,
                                  "--window-size=" + std::to_string(width) + "," + std::to_string(height), "about:blank"};
    // Chromium's own scratch folders (org.chromium.Chromium.*) go into the profile folder,
    // removed with it: in /tmp every run of a browser test left one behind.
    std::vector<std::string> env{"TMPDIR=" + profile_};
    for (char** e = environ; *e; ++e) {
        if (std::string(*e).rfind("TMPDIR=", 0) != 0) env.emplace_back(*e);
    }
    std::vector<char*> envp;
    for (auto& e : env) envp.push_back(e.data());
    envp.push_back(nullptr);
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    pid_ = ::fork();
    if (pid_ < 0) throw std::runtime_error("Browser: fork failed");
    if (pid_ == 0) {
        ::setpgid(0, 0);    // its own group: the renderers and helpers end with it
        ::dup2(in[0], 3);   // chromium reads commands from fd 3
        ::dup2(out[1], 4);  // and writes replies to fd 4
        const int null = ::open("/dev/null", O_WRONLY);
        ::dup2(null, 1);
        ::dup2(null, 2);
        ::execve(argv[0], argv.data(), envp.data());
        ::_exit(127);
    }
    ::close(in[0]);
    ::close(out[1]);
    to_browser_ = in[1];
    from_browser_ = out[0];
    const auto target = call("Target.createTarget", {{"url", "about:blank"}}, false);
    const auto attached = call("Target.attachToTarget", {{"targetId", target.at("targetId")}, {"flatten", true}}, false);
    session_ = attached.at("sessionId");
    call("Page.enable");
    call("Emulation.setDeviceMetricsOverride", {{"width", width}, {"height", height}, {"deviceScaleFactor", 1}, {"mobile", false}});
}

Browser::~Browser()
{
    if (to_browser_ >= 0) ::close(to_browser_);
    if (from_browser_ >= 0) ::close(from_browser_);
    if (pid_ > 0) {
        ::kill(-pid_, SIGTERM);
        bool ended = false;
        for (int i = 0; i < 100 && !(ended = ::waitpid(pid_, nullptr, WNOHANG) == pid_); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(20));
        ::kill(-pid_, SIGKILL);  // whatever of the group is left
        if (!ended) ::waitpid(pid_, nullptr, 0);
    }
    std::error_code ec;
    std::filesystem::remove_all(profile_, ec);
}

nlohmann::json Browser::receive(Clock::time_point deadline)
{
    while (true) {
        const auto end = buffer_.find('\0');
        if (end != std::string::npos) {
            const std::string message = buffer_.substr(0, end);
            buffer_.erase(0, end + 1);
            return nlohmann::json::parse(message);
        }
        const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
        if (left <= 0) throw std::runtime_error("Browser: no answer from chromium in time");
        pollfd p{from_browser_, POLLIN, 0};
        if (::poll(&p, 1, int(left)) <= 0) continue;
        char chunk[65536];
        const ssize_t n = ::read(from_browser_, chunk, sizeof chunk);
        if (n <= 0) throw std::runtime_error("Browser: chromium closed its pipe (did it start? /usr/bin/chromium)");
        buffer_.append(chunk, size_t(n));
    }
}

nlohmann::json Browser::call(const std::string& method, const nlohmann::json& params, bool in_tab)
{
    const int id = next_id_++;
    nlohmann::json message{{"id", id}, {"method", method}, {"params", params}};
    if (in_tab) message["sessionId"] = session_;
    const std::string text = message.dump() + std::string(1, '\0');
    for (size_t done = 0; done < text.size();) {
        const ssize_t n = ::write(to_browser_, text.data() + done, text.size() - done);
        if (n <= 0) throw std::runtime_error("Browser: cannot write to chromium");
        done += size_t(n);
    }
    const auto deadline = Clock::now() + std::chrono::seconds(30);
    while (true) {
        auto reply = receive(deadline);
        if (!reply.contains("id") || reply["id"] != id) continue;  // an event, or another call's answer
        if (reply.contains("error")) throw std::runtime_error("Browser: " + method + ": " + reply["error"].dump());
        return reply.value("result", nlohmann::json::object());
    }
}

void Browser::open(const std::string& url)
{
    call("Page.navigate", {{"url", url}});
    if (!wait_for("document.readyState === 'complete'", std::chrono::seconds(20))) throw std::runtime_error("Browser: " + url + " did not load");
}

nlohmann::json Browser::eval(const std::string& expression)
{
    const auto r = call("Runtime.evaluate", {{"expression", expression}, {"returnByValue", true}, {"awaitPromise", true}});
    if (r.contains("exceptionDetails")) {
        const auto& d = r["exceptionDetails"];
        throw std::runtime_error("Browser: the page threw: " +
                                 (d.contains("exception") ? d["exception"].value("description", d.dump()) : d.dump()));
    }
    return r.at("result").value("value", nlohmann::json());
}

bool Browser::wait_for(const std::string& expression, std::chrono::milliseconds timeout)
{
    const auto deadline = Clock::now() + timeout;
    while (Clock::now() < deadline) {
        const auto v = eval("Boolean(" + expression + ")");
        if (v.is_boolean() && v.get<bool>()) return true;
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    return false;
}

void Browser::screenshot(const std::string& path)
{
    const auto r = call("Page.captureScreenshot", {{"format", "png"}});
    std::ofstream(path, std::ios::binary) << [&] {
        const auto bytes = cpm::base64_decode(r.at("data").get<std::string>());
        return std::string(bytes.begin(), bytes.end());
    }();
}

}  // namespace cpm_test
