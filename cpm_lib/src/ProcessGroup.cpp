#include <cpm/ProcessGroup.hpp>

#include <cpm/Error.hpp>

#include <csignal>
#include <deque>
#include <fstream>
#include <iterator>
#include <set>

namespace cpm {

std::string tail_of_file(const std::string& path, size_t n)
{
    std::ifstream in(path);
    std::deque<std::string> lines;
    for (std::string line; std::getline(in, line);) {
        lines.push_back(line);
        if (lines.size() > n) lines.pop_front();
    }
    std::string out;
    for (const auto& l : lines) out += "    " + l + "\n";
    return out;
}

ProcessGroup::~ProcessGroup()
{
    (void)stop_all();
    {
        std::lock_guard<std::mutex> lock(stdin_mutex_);
        keepalive_ending_ = true;
    }
    keepalive_wake_.notify_all();
    if (keepalive_.joinable()) keepalive_.join();
}

void ProcessGroup::keep_remotes_alive()
{
    std::unique_lock<std::mutex> lock(stdin_mutex_);
    while (!keepalive_wake_.wait_for(lock, std::chrono::seconds(1), [this] { return keepalive_ending_; })) {
        for (auto& m : members_) {
            // One that ended or was told to stop has its input closed: writing fails, harmlessly.
            if (m.child && !m.spec.host.is_local()) (void)m.child->write_stdin("\n");
        }
    }
}

ProcessGroup::Member* ProcessGroup::member(const std::string& name)
{
    for (auto& m : members_) {
        if (m.spec.name == name) return &m;
    }
    return nullptr;
}

const ProcessGroup::Member* ProcessGroup::member(const std::string& name) const
{
    return const_cast<ProcessGroup*>(this)->member(name);
}

void ProcessGroup::launch(Member& m, bool again)
{
    if (again && !m.spec.log.empty()) std::ofstream(m.spec.log, std::ios::app) << "\n--- restarted ---\n";
    {
        std::lock_guard<std::mutex> lock(stdin_mutex_);
        m.child.reset();  // reaped already
    }
    const bool remote = !m.spec.host.is_local();
    std::vector<std::string> argv = m.spec.argv;
    if (remote && !m.spec.env.empty()) {  // the environment there: env NAME=value … program
        argv.insert(argv.begin(), m.spec.env.begin(), m.spec.env.end());
        argv.insert(argv.begin(), "/usr/bin/env");
    }
    std::lock_guard<std::mutex> lock(stdin_mutex_);
    if (remote && !keepalive_.joinable()) keepalive_ = std::thread([this] { keep_remotes_alive(); });
    m.child.emplace(ProcessOptions{.argv = remote ? remote_command(m.spec.host, argv, m.spec.stop_grace) : argv,
                                   .env = remote ? std::vector<std::string>{} : m.spec.env,
                                   .stdout_path = m.spec.capture_stdout ? "" : m.spec.log,
                                   .stderr_path = m.spec.log,
                                   .append_output = again,
                                   .capture_stdout = m.spec.capture_stdout,
                                   .pipe_stdin = remote,
                                   .own_process_group = m.spec.own_process_group,
                                   .die_with_parent = true});
    m.end.reset();
}

ChildProcess& ProcessGroup::start(ProcessSpec spec)
{
    if (spec.name.empty()) throw Error("process group: a process needs a name");
    if (member(spec.name)) throw Error("process group: the name '" + spec.name + "' is taken");
    Member* added = nullptr;
    {
        std::lock_guard<std::mutex> lock(stdin_mutex_);
        added = &members_.emplace_back();
        added->spec = std::move(spec);
    }
    Member& m = *added;
    try {
        launch(m, false);
    } catch (...) {
        std::lock_guard<std::mutex> lock(stdin_mutex_);
        members_.pop_back();
        throw;
    }
    return *m.child;
}

std::vector<ProcessEvent> ProcessGroup::poll()
{
    std::vector<ProcessEvent> events;
    for (auto& m : members_) {
        if (!m.child || m.end) continue;
        auto end = m.child->ended();
        if (!end) continue;
        m.end = as_told(m, *end);
        ProcessEvent e = event_of(m, *m.end);
        if (m.spec.restart && !end->ok()) {
            try {
                launch(m, true);
                ++m.restarts;
                e.restarted = true;
                e.restarts = m.restarts;
            } catch (const std::exception& ex) {  // told as an end that was not restarted, with why
                m.end = end;
                if (!m.spec.log.empty()) std::ofstream(m.spec.log, std::ios::app) << "--- cannot restart it: " << ex.what() << " ---\n";
            }
        }
        events.push_back(std::move(e));
    }
    return events;
}

void ProcessGroup::interrupt(Member& m)
{
    // A remote process is stopped by its `cpm host run` when its ssh's input closes; a signal to
    // ssh would end the connection without waiting for the process's end.
    if (m.spec.host.is_local()) m.child->ask_to_stop(SIGINT);
    else {
        std::lock_guard<std::mutex> lock(stdin_mutex_);
        m.child->close_stdin();
    }
}

void ProcessGroup::stop(Member& m)
{
    // A remote one's grace is spent there, then its SIGTERM and the end of what it left
    // (run_until_input_ends); the connection gets 3 s more. Ending its ssh sooner would make a
    // process slow to stop (killed there in time) read as a lost host.
    const bool remote = !m.spec.host.is_local();
    const auto remote_stop = kRemoteTermWait + kRemoteGroupEndWait + std::chrono::milliseconds(3000);
    m.end = m.child->wait(m.spec.stop_grace + (remote ? remote_stop : std::chrono::milliseconds(0)));
    if (!m.end) {
        m.end = m.child->stop(std::chrono::seconds(2));
        // Its ssh, ended here (ssh then exits 255): the run's doing, not a lost host.
        if (remote && m.end->signal == 0 && m.end->code == 255) m.end = ExitStatus{.code = -1, .signal = SIGTERM};
    }
    m.end = as_told(m, *m.end);
}

ExitStatus ProcessGroup::as_told(const Member& m, const ExitStatus& end)
{
    // What ssh passes on of a remote process: its exit code, or 128 + the signal that ended it
    // (cpm host run); 255 is ssh's own failure, kept as it is (event_of calls it a lost host).
    if (m.spec.host.is_local() || end.signal != 0 || end.code <= 128 || end.code >= 128 + 65) return end;
    return ExitStatus{.code = -1, .signal = end.code - 128};
}

ProcessEvent ProcessGroup::event_of(const Member& m, const ExitStatus& end)
{
    ProcessEvent e{m.spec.name, end, false, m.restarts, m.spec.host.name};
    e.host_lost = !m.spec.host.is_local() && end.signal == 0 && end.code == 255;
    return e;
}

std::string ProcessEvent::describe() const
{
    if (host_lost) return "lost with host " + host + " (ssh ended: the host was not reached or the connection broke)";
    return end.describe() + (host.empty() ? "" : " on " + host);
}

ChildProcess& ProcessGroup::restart(const std::string& name)
{
    Member* m = member(name);
    if (!m) throw Error("process group: no process '" + name + "' to restart");
    if (m->child && !m->end) {
        interrupt(*m);
        stop(*m);
    }
    launch(*m, true);
    ++m->restarts;
    return *m->child;
}

std::vector<ProcessEvent> ProcessGroup::stop_all()
{
    std::set<int> orders;
    for (const auto& m : members_) orders.insert(m.spec.stop_order);
    for (int order : orders) {
        std::vector<Member*> now;
        for (auto& m : members_) {
            if (m.spec.stop_order == order && m.child && !m.end) now.push_back(&m);
        }
        for (Member* m : now) interrupt(*m);
        for (Member* m : now) stop(*m);
    }
    std::vector<ProcessEvent> ends;
    for (const auto& m : members_) {
        if (m.end) ends.push_back(event_of(m, *m.end));
    }
    return ends;
}

ChildProcess* ProcessGroup::find(const std::string& name)
{
    Member* m = member(name);
    return m && m->child ? &*m->child : nullptr;
}

std::optional<ExitStatus> ProcessGroup::end_of(const std::string& name) const
{
    const Member* m = member(name);
    return m ? m->end : std::nullopt;
}

int ProcessGroup::restarts_of(const std::string& name) const
{
    const Member* m = member(name);
    return m ? m->restarts : 0;
}

std::string ProcessGroup::tail(const std::string& name, size_t n) const
{
    const Member* m = member(name);
    return m && !m->spec.log.empty() ? tail_of_file(m->spec.log, n) : std::string();
}

std::string ProcessGroup::log_text(const std::string& name) const
{
    const Member* m = member(name);
    if (!m || m->spec.log.empty()) return "";
    std::ifstream in(m->spec.log);
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

std::vector<std::string> ProcessGroup::names() const
{
    std::vector<std::string> out;
    for (const auto& m : members_) out.push_back(m.spec.name);
    return out;
}

}  // namespace cpm
