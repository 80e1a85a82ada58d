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
    m.child.reset();  // reaped already
    m.child.emplace(ProcessOptions{.argv = m.spec.argv,
                                   .env = m.spec.env,
                                   .stdout_path = m.spec.capture_stdout ? "" : m.spec.log,
                                   .stderr_path = m.spec.log,
                                   .append_output = again,
                                   .capture_stdout = m.spec.capture_stdout,
                                   .own_process_group = m.spec.own_process_group,
                                   .die_with_parent = true});
    m.end.reset();
}

ChildProcess& ProcessGroup::start(ProcessSpec spec)
{
    if (spec.name.empty()) throw Error("process group: a process needs a name");
    if (member(spec.name)) throw Error("process group: the name '" + spec.name + "' is taken");
    if (!spec.host.empty()) {
        throw Error("process group: " + spec.name + ": host '" + spec.host + "': starting processes on other hosts is not supported yet");
    }
    Member& m = members_.emplace_back();
    m.spec = std::move(spec);
    try {
        launch(m, false);
    } catch (...) {
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
        m.end = end;
        ProcessEvent e{m.spec.name, *end, false, m.restarts};
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

void ProcessGroup::stop(Member& m)
{
    m.end = m.child->wait(m.spec.stop_grace);
    if (!m.end) m.end = m.child->stop(std::chrono::seconds(2));
}

ChildProcess& ProcessGroup::restart(const std::string& name)
{
    Member* m = member(name);
    if (!m) throw Error("process group: no process '" + name + "' to restart");
    if (m->child && !m->end) {
        m->child->signal(SIGINT);
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
        for (Member* m : now) m->child->signal(SIGINT);
        for (Member* m : now) stop(*m);
    }
    std::vector<ProcessEvent> ends;
    for (const auto& m : members_) {
        if (m.end) ends.push_back({m.spec.name, *m.end, false, m.restarts});
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
