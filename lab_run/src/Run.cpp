#include <cpm/lab/Run.hpp>

#include <cpm/AsyncReader.hpp>
#include <cpm/ChildProcess.hpp>
#include <cpm/CommandLine.hpp>
#include <cpm/Discovery.hpp>
#include <cpm/HistoryClient.hpp>
#include <cpm/Participant.hpp>
#include <cpm/RemoteHost.hpp>
#include <cpm/init.hpp>
#include <cpm/read_text_file.hpp>
#include <cpm/ProcessGroup.hpp>
#include <cpm/Security.hpp>
#include <cpm/TimeMaster.hpp>
#include <cpm/Timer.hpp>
#include <cpm/timer_ids.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/stamp_message.hpp>
#include <cpm/topics.hpp>

#include <HistoryStatus.h>
#include <Log.h>
#include <StopRequest.h>
#include <VehicleState.h>
#include <cpm_topic_types.hpp>

#include <cpm/rtdb/HistoryService.hpp>
#include <cpm/rtdb/TopicProbe.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <fcntl.h>
#include <filesystem>
#include <fstream>
#include <functional>
#include <future>
#include <map>
#include <mutex>
#include <optional>
#include <regex>
#include <set>
#include <sstream>
#include <sys/file.h>
#include <thread>
#include <unistd.h>

namespace cpm::lab {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

std::string utc_now_compact()
{
    const std::time_t t = std::time(nullptr);
    std::tm tm{};
    ::gmtime_r(&t, &tm);
    char b[32];
    std::strftime(b, sizeof b, "%Y%m%dT%H%M%SZ", &tm);
    return b;
}

/// The last line of a file that is a JSON object (a cpm program's statistics at its end).
nlohmann::json last_json(const std::string& path)
{
    std::ifstream in(path);
    nlohmann::json found;
    for (std::string line; std::getline(in, line);) {
        if (line.empty() || line[0] != '{') continue;
        try {
            found = nlohmann::json::parse(line);
        } catch (const std::exception&) {
        }
    }
    return found;
}

}  // namespace

std::string recording_loss(const std::map<std::string, uint64_t>& lost_by_topic)
{
    uint64_t total = 0;
    std::string topics;
    for (const auto& [topic, n] : lost_by_topic) {
        total += n;
        topics += (topics.empty() ? "" : ", ") + topic + " " + std::to_string(n);
    }
    return total ? std::to_string(total) + " samples never reached the recorder (" + topics + "; it could not keep up)" : "";
}

std::map<std::string, uint64_t> recording_lost_by_topic(const nlohmann::json& recording)
{
    std::map<std::string, uint64_t> out;
    if (!recording.is_object() || !recording.contains("lost_by_topic")) return out;
    for (const auto& [topic, n] : recording["lost_by_topic"].items()) out[topic] = n.get<uint64_t>();
    return out;
}

namespace {

/// The lock file a cpm lab run holds on its domain (and on its controllers') while it lasts.
std::string run_lock_path(int domain) { return "/tmp/cpm_lab_run_domain_" + std::to_string(domain) + ".lock"; }

/// The domain, claimed for the run: no other cpm lab run on this host has it (a lock file held
/// while the run lasts), and discovery sees nobody on it. Throws std::runtime_error naming who
/// is there.
class DomainClaim
{
public:
    DomainClaim(int domain, const ParticipantOptions& options, const Scenario& s, const std::string& what = "")
    {
        const std::string named = what.empty() ? "domain " + std::to_string(domain) : what + " " + std::to_string(domain);
        const std::string remedy = what.empty() ? "give this one another domain (domain: in the scenario, or --dds_domain)"
                                                : "give it another one (domain: of the controller in the scenario)";
        const std::string lock = run_lock_path(domain);
        fd_ = ::open(lock.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666);
        if (fd_ >= 0 && ::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
            ::close(fd_);
            throw cpm::Error(named + " is taken by another cpm lab run on this host (" + lock + " is locked); " + remedy);
        }
        // The probe over UDP only: a shared-memory port it freed would be taken over at once by
        // the run's own participant, unreachable for a while by a peer that had seen the probe
        // (a monitor left open on the domain).
        ParticipantOptions udp_only = options;
        udp_only.shared_memory = false;
        rtdb::TopicProbe probe(udp_only);
        std::this_thread::sleep_for(std::chrono::milliseconds(1500));  // discovery over loopback and shared memory
        // A cpm monitor only watches (and sends StopRequests when allowed): one left open on the
        // domain between runs is welcome.
        auto others = probe.participants_seen();
        std::erase_if(others, [](const rtdb::ParticipantSeen& p) { return p.name.rfind("cpm_monitor", 0) == 0; });
        if (!others.empty()) {
            std::string names;
            for (const auto& p : others) names += (names.empty() ? "" : ", ") + p.name + where(p, s);
            if (fd_ >= 0) ::close(fd_);
            throw cpm::Error(named + " is in use by " + std::to_string(others.size()) + " participant(s): " + names + "; stop them or " + remedy);
        }
    }
    /// " on host car5 (10.0.0.21)" for a participant that announced a host's address; else "".
    static std::string where(const rtdb::ParticipantSeen& p, const Scenario& s)
    {
        for (const auto& a : p.addresses) {
            for (const auto& h : s.hosts) {
                if (h.address == a) return " on host " + h.name + " (" + a + ")";
            }
        }
        return "";
    }
    ~DomainClaim()
    {
        if (fd_ >= 0) ::close(fd_);
    }
    DomainClaim(const DomainClaim&) = delete;
    DomainClaim& operator=(const DomainClaim&) = delete;

private:
    int fd_ = -1;
};

/// On the simulated clock, a sample written before the recorder's reader matched its writer is
/// lost to the recording, and which are lost would depend on discovery's timing (a run recorded
/// its cars' first two observations, the next one not). The clock starts once cpm_history's recorder has a
/// reader of every topic the run's processes write that the scenario records.
class RecorderGate
{
public:
    explicit RecorderGate(const Scenario& s)
    {
        for (const auto& t : s.record.topics) {
            if (t != "*") include_.emplace_back(cpm::cli::glob_regex(t));
        }
        for (const auto& t : s.record.exclude) exclude_.emplace_back(cpm::cli::glob_regex(t));
    }
    void on_discovery(const DiscoveryEvent& e)
    {
        std::lock_guard<std::mutex> lock(mutex_);
        if (e.kind == DiscoveryEvent::Kind::participant_found) names_[e.prefix()] = e.participant_name;
        if (e.kind == DiscoveryEvent::Kind::writer_found) writers_.emplace(e.prefix(), e.topic);
        if (e.kind == DiscoveryEvent::Kind::reader_found) readers_.emplace(e.prefix(), e.topic);
        changed_.notify_all();
    }
    /// Waits (up to `timeout`) until the recorder reads every recorded topic written; says which
    /// it still lacks when it gives up.
    void wait(std::chrono::milliseconds timeout, FILE* progress)
    {
        std::unique_lock<std::mutex> lock(mutex_);
        std::set<std::string> missing;
        const bool ready = changed_.wait_for(lock, timeout, [&] { return (missing = unread()).empty(); });
        // This process sees the recorder's readers about when the writers' processes do; each
        // writer then matches them on its own. Half a second for that (no DDS API here tells
        // when another process's writer matched): without it, 1 intersection run in 2 lost its
        // cars' first observation to the recording; with it, none in the 8 runs since.
        lock.unlock();
        if (ready) std::this_thread::sleep_for(std::chrono::milliseconds(500));
        if (!ready && progress) {
            std::string names;
            for (const auto& t : missing) names += (names.empty() ? "" : ", ") + t;
            std::fprintf(progress, "cpm lab run: the recorder has no reader of %s after %lld s; the clock starts anyway (their first samples may be missing)\n",
                         names.c_str(), (long long)std::chrono::duration_cast<std::chrono::seconds>(timeout).count());
        }
    }

private:
    bool recorded(const std::string& topic) const
    {
        const auto full = [&](const std::regex& r) { return std::regex_match(topic, r); };
        return (include_.empty() || std::any_of(include_.begin(), include_.end(), full)) && std::none_of(exclude_.begin(), exclude_.end(), full);
    }
    std::set<std::string> unread() const
    {
        std::set<std::string> read, missing;
        for (const auto& [prefix, topic] : readers_) {
            if (auto n = names_.find(prefix); n != names_.end() && n->second == rtdb::recorder_name("cpm_history")) read.insert(topic);
        }
        for (const auto& [prefix, topic] : writers_) {
            const auto n = names_.find(prefix);
            if (n == names_.end() || n->second.rfind("cpm_history", 0) == 0 || n->second == "cpm_lab_run") continue;
            if (recorded(topic) && !read.count(topic)) missing.insert(topic);
        }
        return missing;
    }
    std::vector<std::regex> include_, exclude_;
    mutable std::mutex mutex_;
    std::condition_variable changed_;
    std::map<std::array<uint8_t, 12>, std::string> names_;
    std::multimap<std::array<uint8_t, 12>, std::string> writers_, readers_;
};

/// What the lab says while it runs: the history's counts and the timers' missed ticks.
class RunWatch
{
public:
    explicit RunWatch(Participant& p)
        : status_([this](std::vector<HistoryStatus>& s) { on_status(s); }, p, topics::history_status.name, topics::history_status.reader),
          log_([this](std::vector<Log>& l) { on_log(l); }, p, topics::log.name, topics::log.reader)
    {
    }
    uint64_t recorded() const { return recorded_; }
    uint64_t missed() const
    {
        std::lock_guard<std::mutex> lock(mutex_);
        uint64_t n = 0;
        for (const auto& [timer, count] : missed_) n += count;
        return n;
    }

private:
    void on_status(std::vector<HistoryStatus>& statuses)
    {
        for (const auto& s : statuses) {
            uint64_t n = 0;
            for (const auto& t : s.topics()) n += t.samples();
            recorded_ = n;
        }
    }
    void on_log(std::vector<Log>& lines)
    {
        std::lock_guard<std::mutex> lock(mutex_);
        for (const auto& l : lines) {
            if (const auto said = timer_missed_ticks(l.content())) missed_[said->first] = std::max(missed_[said->first], said->second);
        }
    }

    mutable std::mutex mutex_;
    std::map<std::string, uint64_t> missed_;
    std::atomic<uint64_t> recorded_{0};
    AsyncReader<HistoryStatus> status_;
    AsyncReader<Log> log_;
};

/// How the run reaches a host of the scenario (this host: a RemoteHost that is local).
RemoteHost remote_of(const Scenario& s, const RunSettings& settings, const std::string& host_name)
{
    const HostSpec* h = s.host(host_name);
    if (!h || h->ssh.empty()) return {};
    return {.name = h->name,
            .ssh = h->ssh,
            .ssh_options = s.ssh_config.empty() ? std::vector<std::string>{} : std::vector<std::string>{"-F", s.ssh_config},
            .cpm_prefix = h->cpm,
            .shared_connection_dir = settings.ssh_shared_dir};
}

/// The run's ssh connections, one per other host, shared by every command the run sends there
/// (a three-host start made eleven key exchanges, 3 s of it): their private folder, made when
/// the scenario has other hosts; the connections ended and the folder removed at the end.
class SharedConnections
{
public:
    SharedConnections(const Scenario& s, RunSettings& settings) : s_(s), settings_(settings)
    {
        if (std::none_of(s.hosts.begin(), s.hosts.end(), [](const HostSpec& h) { return !h.ssh.empty(); })) return;
        char dir[] = "/tmp/cpm-ssh-XXXXXX";  // short: a socket's path has at most 107 bytes
        if (::mkdtemp(dir) == nullptr) throw cpm::Error(std::string("cannot make a folder for the run's ssh connections in /tmp: ") + std::strerror(errno));
        settings.ssh_shared_dir = dir;
    }
    ~SharedConnections()
    {
        if (settings_.ssh_shared_dir.empty()) return;
        for (const auto& h : s_.hosts) close_shared_connection(remote_of(s_, settings_, h.name));
        std::error_code ec;
        fs::remove_all(settings_.ssh_shared_dir, ec);
    }
    SharedConnections(const SharedConnections&) = delete;
    SharedConnections& operator=(const SharedConnections&) = delete;

private:
    const Scenario& s_;
    const RunSettings& settings_;
};

std::string milliseconds(int64_t ns)
{
    char b[32];
    std::snprintf(b, sizeof b, "%.3f ms", double(ns) / 1e6);
    return b;
}

/// A port a process of the run listens on: "tcp:8080", the scenario's key that gives it, its host ("" this one).
struct ListenPort
{
    std::string port, key, host, instead;
};

/// The ports the run's servers take: the monitor's web page, the discovery server's.
std::vector<ListenPort> listen_ports(const Scenario& s)
{
    auto here = [&](const std::string& host) { return s.host(host) && !s.host(host)->ssh.empty() ? host : std::string(); };
    std::vector<ListenPort> out;
    if (s.monitor_port)
        out.push_back({"tcp:" + std::to_string(*s.monitor_port), "monitor", here(s.monitor_host), "choose another port (monitor: N, or --monitor N; none: --monitor off)"});
    if (s.discovery_server)
        out.push_back({"udp:" + std::to_string(Scenario::kDiscoveryServerPort), "discovery_server", here(s.discovery_server_host),
                       "stop what listens there (another discovery server?) or put the server on another host"});
    return out;
}

/// "<file>: <key>: <port> cannot be taken on <where> (<why>)..." for each port named in `taken`
/// ("tcp:8080 Address already in use" lines).
void name_taken_ports(const Scenario& s, const std::string& host, const std::string& taken, std::vector<Diagnostic>& errors)
{
    std::istringstream lines(taken);
    for (std::string line; std::getline(lines, line);) {
        const std::string port = line.substr(0, line.find(' ')), why = line.find(' ') == std::string::npos ? "" : line.substr(line.find(' ') + 1);
        for (const auto& p : listen_ports(s)) {
            if (p.host != host || p.port != port) continue;
            errors.push_back({s.file + ": " + p.key, port + " cannot be taken on " + (host.empty() ? std::string("this host") : "host " + host) + " (" +
                                                         why + "): " + p.instead});
        }
    }
}

/// All a command prints on stdout ("" when it cannot run); `ended` (if given) says how it
/// ended: "exited with code 255", "did not end within 10 s", or why it could not start.
std::string output_of(const std::vector<std::string>& argv, std::string* ended = nullptr)
{
    try {
        ChildProcess c({.argv = argv, .capture_stdout = true});
        std::string out;
        while (auto line = c.read_line()) out += *line + "\n";
        const auto end = c.wait(std::chrono::seconds(10));
        if (ended) *ended = end ? end->describe() : "did not end within 10 s";
        return out;
    } catch (const cpm::Error& e) {
        if (ended) *ended = e.what();
        return "";
    }
}

/// The first line a command prints ("" when it prints none or cannot run), and how it ended.
std::string first_line_of(const std::vector<std::string>& argv, std::string* ended = nullptr)
{
    const std::string out = output_of(argv, ended);
    return out.substr(0, out.find('\n'));
}

/// One other host: reached with ssh, the same cpm as here (`ours`), its clock within
/// max_clock_offset, the ports the run's servers there take free. What is wrong is added to
/// `errors`.
RunResult::Host check_host(const Scenario& s, const RunSettings& settings, const HostSpec& h, const std::string& ours, std::vector<Diagnostic>& errors)
{
    RunResult::Host entry{.name = h.name, .address = h.address};
    const RemoteHost remote = remote_of(s, settings, h.name);
    const std::string where = s.file + ": hosts." + h.name;
    if (remote.is_local()) return entry;
    std::vector<std::string> ports;  // that its servers take there
    for (const auto& p : listen_ports(s)) {
        if (p.host == h.name) ports.push_back(p.port);
    }
    // Asked twice before the host is refused: once (2026-12-07, the first tests of a fresh
    // clone's suite on a busy machine) it printed nothing and said nothing, and the next test
    // reached the same host at once.
    std::string ended, theirs;
    for (int attempt = 0; attempt < 2 && theirs.empty(); ++attempt) {
        if (attempt > 0) std::this_thread::sleep_for(std::chrono::milliseconds(500));
        theirs = first_line_of(ssh_command(remote, {remote.program("cpm"), "--version"}), &ended);
    }
    if (theirs.empty()) {
        errors.push_back({where, "cannot run " + remote.program("cpm") + " there with ssh " + h.ssh + " (ssh " + ended +
                                     "; the host unreachable, ssh asking for a password or a key, or cpm not installed there)"});
        return entry;
    }
    if (theirs != ours) {
        errors.push_back({where, "runs " + theirs + ", this host " + ours + ": install the same cpm on every host"});
        return entry;
    }
    if (!ports.empty()) {
        ports.insert(ports.begin(), {remote.program("cpm"), "host", "ports"});
        name_taken_ports(s, h.name, output_of(ssh_command(remote, ports)), errors);
    }
    try {
        const auto clock = measure_clock(remote);
        entry.clock_offset_ns = clock.offset_ns;
        entry.rtt_ns = clock.rtt_ns;
        if (uint64_t(std::llabs(clock.offset_ns)) > s.max_clock_offset_ns) {
            errors.push_back({where, "its clock is " + milliseconds(clock.offset_ns) + " off this host's (measured to ±" +
                                         milliseconds(clock.rtt_ns / 2) + "), more than max_clock_offset " +
                                         milliseconds(int64_t(s.max_clock_offset_ns)) +
                                         ": synchronise the hosts' clocks (chrony or NTP) and run again"});
        }
    } catch (const cpm::Error& e) {
        errors.push_back({where, e.what()});
    }
    return entry;
}

/// Every other host, before anything starts anywhere, each on a thread of its own (a host is a
/// few ssh round trips): check_host; and the ports this host's servers take. Throws
/// ScenarioError naming each host that is not fit, in the scenario's order.
std::vector<RunResult::Host> check_hosts(const Scenario& s, const RunSettings& settings)
{
    const std::string ours = first_line_of({(fs::path(settings.bin_dir) / "cpm").string(), "--version"});
    std::vector<std::vector<Diagnostic>> errors(s.hosts.size());
    std::vector<std::future<RunResult::Host>> checks;
    for (size_t i = 0; i < s.hosts.size(); ++i)
        checks.push_back(std::async(std::launch::async, [&, i] { return check_host(s, settings, s.hosts[i], ours, errors[i]); }));
    std::vector<RunResult::Host> out;
    std::vector<Diagnostic> all;
    std::string taken_here;
    for (const auto& p : listen_ports(s)) {
        if (const std::string why = p.host.empty() ? port_taken(p.port.substr(0, 3), std::stoi(p.port.substr(4))) : ""; !why.empty())
            taken_here += p.port + " " + why + "\n";
    }
    name_taken_ports(s, "", taken_here, all);
    for (size_t i = 0; i < checks.size(); ++i) {
        out.push_back(checks[i].get());
        all.insert(all.end(), errors[i].begin(), errors[i].end());
    }
    if (!all.empty()) throw ScenarioError(all);
    return out;
}

/// Runs a command on another host with `input` as its stdin; whether it exited 0.
bool run_there(const RemoteHost& remote, const std::vector<std::string>& argv, const std::string& input)
{
    ChildProcess c({.argv = ssh_command(remote, argv), .pipe_stdin = true});
    const bool written = c.write_stdin(input);
    c.close_stdin();
    const auto end = c.wait(std::chrono::seconds(30));
    return written && end && end->ok();
}

/// The run's folders on the other hosts, removed once their processes ended (the logs are here).
void remove_from_hosts(const Scenario& s, const RunSettings& settings)
{
    for (const auto& h : s.hosts) {
        const RemoteHost remote = remote_of(s, settings, h.name);
        if (!remote.is_local()) (void)run_there(remote, {"rm", "-rf", remote_run_dir(settings)}, "");
    }
}

/// The files each process on another host reads, copied into the run's folder there (made
/// first): one ssh per host, the files in one stream of "<bytes> <path>" lines each followed by
/// the file. Readable by their owner only (a node's private key among them). Throws
/// ScenarioError naming the host and what could not be copied.
void copy_to_hosts(const Scenario& s, const std::vector<ProcessPlan>& plan, const RunSettings& settings)
{
    std::vector<Diagnostic> errors;
    for (const auto& h : s.hosts) {
        const RemoteHost remote = remote_of(s, settings, h.name);
        if (remote.is_local()) continue;
        const std::string there = remote_run_dir(settings);
        std::set<std::string> done;
        std::string stream, what;
        for (const auto& p : plan) {
            if (p.host != h.name) continue;
            for (const auto& [local, copy] : p.copies) {
                if (!done.insert(copy).second) continue;
                const std::string text = read_text_file(local, "file for " + p.name);
                stream += std::to_string(text.size()) + " " + copy + "\n" + text;
                what += (what.empty() ? "" : ", ") + local;
            }
        }
        const std::string script = "umask 077 && mkdir -p " + shell_quote(there) +
                                   " && while read -r n f; do mkdir -p \"$(dirname \"$f\")\" && head -c \"$n\" > \"$f\" || exit 1; done";
        if (!run_there(remote, {"/bin/sh", "-c", script}, stream)) {
            errors.push_back({s.file + ": hosts." + h.name, "cannot make the run's folder " + there + " there" +
                                                               (what.empty() ? std::string() : " with " + what)});
        }
    }
    if (!errors.empty()) throw ScenarioError(errors);
}

/// The run's spec of a planned process: its log in the run's folder, the run's domain, QoS and
/// transports.
ProcessSpec spec_of(const ProcessPlan& p, const fs::path& dir, const RunSettings& settings, const std::string& qos, const Scenario& s)
{
    ProcessSpec spec{.name = p.name,
                     .argv = p.argv,
                     .env = {"CPM_DOMAIN_ID=" + std::to_string(settings.domain),
                             std::string("CPM_SHARED_MEMORY=") + (settings.shared_memory ? "on" : "off")},
                     .log = (dir / (p.name + ".log")).string(),
                     .restart = p.restart,
                     .stop_order = p.stop_order,
                     // The history closes the recording on its way out: it may take a while.
                     .stop_grace = std::chrono::seconds(p.name == "cpm_history" ? 30 : 5)};
    if (!qos.empty()) spec.env.push_back(std::string(kQosOverridesVariable) + "=" + qos);
    spec.host = remote_of(s, settings, p.host);
    return spec;
}

/// The cars of a real-time run that have sent their first state: each car's programs are up
/// (over ssh a few seconds into the run), so its lab time can start (as cpm_lab's control
/// centre waits for its vehicles).
class CarsUp
{
public:
    CarsUp(Participant& participant, std::set<int> cars)
        : waiting_(std::move(cars)),
          states_([this](std::vector<VehicleState>& states) { on_states(states); }, participant, topics::vehicle_state.name,
                  topics::vehicle_state.reader)
    {
    }
    /// Waits up to `timeout` (or until `cancelled`) for every car's first state; the cars still
    /// silent then.
    std::set<int> wait(std::chrono::milliseconds timeout, const std::function<bool()>& cancelled)
    {
        const auto deadline = Clock::now() + timeout;
        std::unique_lock<std::mutex> lock(mutex_);
        while (!waiting_.empty() && Clock::now() < deadline && !cancelled()) {
            changed_.wait_for(lock, std::chrono::milliseconds(50));
        }
        return waiting_;
    }
    std::set<int> waiting() const
    {
        std::lock_guard<std::mutex> lock(mutex_);
        return waiting_;
    }

private:
    void on_states(const std::vector<VehicleState>& states)
    {
        std::lock_guard<std::mutex> lock(mutex_);
        for (const auto& state : states) waiting_.erase(state.vehicle_id());
        changed_.notify_all();
    }
    mutable std::mutex mutex_;
    std::condition_variable changed_;
    std::set<int> waiting_;
    AsyncReader<VehicleState> states_;
};

/// The lab's clock for one run, started on a thread of its own: simulated time driven through
/// the timers' ticks, or real time, which starts once every car has sent its first state
/// (a second later, together, when a planner waits for the start).
class LabClock
{
public:
    /// `progress` (may be null) is told when a real-time run's lab time starts.
    LabClock(Participant& participant, const RunSettings& settings, const Timeouts& timeouts, std::function<void()> before_start,
             FILE* progress)
        : participant_(participant), master_(participant), settings_(settings), timeouts_(timeouts),
          before_start_(std::move(before_start)), progress_(progress)
    {
    }
    ~LabClock() { stop(); }  // also when the run unwinds: the clock's thread waits for its timers otherwise
    LabClock(const LabClock&) = delete;
    LabClock& operator=(const LabClock&) = delete;

    /// Starts it: `timers` every timer of the run (simulated time steps them), `planners` those
    /// a real-time start waits for, `cars` each car with its processes (named when a car stays
    /// silent). A clock that cannot start says why through ended().
    void start(const std::vector<std::string>& timers, const std::vector<std::string>& planners,
               const std::map<int, std::vector<std::string>>& cars)
    {
        if (simulated()) {
            thread_ = std::thread([this, timers] {
                try {
                    // timeouts.start for every process to come up and join (as for a start in real
                    // time: over ssh on a busy host too), then timeouts.step for each step.
                    master_.run_simulated(timers, settings_.duration_ns, step_timeout(), [this] {
                        if (before_start_) before_start_();
                        stepping_since_ = std::chrono::steady_clock::now();
                    }, start_timeout());
                    until_ = settings_.duration_ns;
                    stepped_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - stepping_since_).count();
                } catch (const std::exception& e) {
                    error_ = std::string("the simulated clock stopped: ") + e.what();
                }
                done_ = true;
            });
            return;
        }
        thread_ = std::thread([this, planners, cars] {
            try {
                const auto since = std::chrono::steady_clock::now();
                wait_for_cars(cars);
                if (stopped_) return;  // stopped while it waited: nothing to start
                real_start_ = planners.empty() ? cpm::get_time_ns()
                                               : master_.start_real_time(planners, std::chrono::milliseconds(1000), start_timeout());
                started_ = true;
                if (progress_) {
                    // Over ssh the cars come up seconds late: the run's duration counts from here.
                    std::fprintf(progress_, "cpm lab run: lab time starts, %.1f s after the processes were started%s\n",
                                 std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count(),
                                 cars.empty() ? "" : " (every car has sent its first state)");
                    std::fflush(progress_);
                }
            } catch (const std::exception& e) {
                error_ = std::string("the lab clock could not start: ") + e.what();
                done_ = true;
            }
        });
    }
    bool simulated() const { return settings_.time == TimeMode::simulated; }
    /// A simulated clock that ran to its end: the real seconds from its first step to its last.
    double stepped_seconds() const { return done_ ? stepped_.load() : 0; }
    /// Lab time now: the simulated clock's last step, or real time since the start (0 before).
    uint64_t now() const
    {
        if (simulated()) return done_ && error_.empty() ? until_.load() : master_.simulated_now();
        if (!started_) return 0;
        const uint64_t t = cpm::get_time_ns();  // once: two reads in one expression may come in either order
        return std::min(settings_.duration_ns, t - std::min(t, real_start_.load()));
    }
    /// What the start still waits for ("" once started): "car 6's first state".
    std::string waiting_for() const
    {
        if (simulated() || started_ || done_) return "";
        std::lock_guard<std::mutex> lock(cars_mutex_);
        if (!cars_up_) return "";
        const auto silent = cars_up_->waiting();
        std::string out;
        for (int car : silent) out += (out.empty() ? "" : ", ") + std::to_string(car);
        if (silent.empty()) return "";
        return silent.size() == 1 ? "car " + out + "'s first state" : "the first states of cars " + out;
    }
    /// Whether the run's duration has passed; `error` says why the clock stopped or never started.
    bool ended(std::string& error) const
    {
        if (done_ && !error_.empty()) {
            error = error_;
            return true;
        }
        if (!simulated()) return started_ && now() >= settings_.duration_ns;
        return done_;
    }
    /// Stops every timer of the lab and waits for the clock's thread.
    void stop()
    {
        if (stopped_) return;
        stopped_ = true;
        master_.stop_all();
        if (thread_.joinable()) thread_.join();
    }

private:
    /// Until every car has sent its first state (timeouts.start, as for the timers of a
    /// simulated run); throws naming the silent cars and their processes.
    void wait_for_cars(const std::map<int, std::vector<std::string>>& cars)
    {
        std::set<int> ids;
        for (const auto& [car, processes] : cars) ids.insert(car);
        if (ids.empty()) return;
        {
            std::lock_guard<std::mutex> lock(cars_mutex_);
            cars_up_.emplace(participant_, ids);
        }
        const auto silent = cars_up_->wait(start_timeout(), [this] { return stopped_.load(); });
        {
            std::lock_guard<std::mutex> lock(cars_mutex_);
            cars_up_.reset();  // its reader of every state is needed no more
        }
        if (silent.empty() || stopped_) return;
        std::string named;
        for (int car : silent) {
            named += (named.empty() ? "" : "; ") + std::string("car ") + std::to_string(car) + " (";
            const auto& processes = cars.at(car);
            for (size_t i = 0; i < processes.size(); ++i) named += (i ? ", '" : "'") + processes[i] + "'";
            named += ")";
        }
        throw Error("no state within " + std::to_string(start_timeout().count()) + " ms from " + named);
    }
    std::chrono::milliseconds start_timeout() const { return std::chrono::milliseconds(timeouts_.start_ns / 1'000'000); }
    std::chrono::milliseconds step_timeout() const { return std::chrono::milliseconds(timeouts_.step_ns / 1'000'000); }
    Participant& participant_;
    TimeMaster master_;
    const RunSettings& settings_;
    const Timeouts timeouts_;
    const std::function<void()> before_start_;
    FILE* const progress_;
    std::thread thread_;
    std::atomic<bool> done_{false};
    std::atomic<bool> started_{false};  // real time: the lab's time runs from real_start_
    std::atomic<uint64_t> until_{0};
    std::string error_;  // written by the thread before done_
    std::chrono::steady_clock::time_point stepping_since_;  // the thread's
    std::atomic<double> stepped_{0};
    std::atomic<uint64_t> real_start_{0};
    std::atomic<bool> stopped_{false};
    mutable std::mutex cars_mutex_;
    std::optional<CarsUp> cars_up_;  // while a real-time start waits for the cars
};

/// Marks the host of a process that ended with it lost (ssh ended without the process's end).
void mark_host_lost(std::vector<RunResult::Host>& hosts, const ProcessEvent& e)
{
    for (auto& h : hosts) h.lost = h.lost || (e.host_lost && h.name == e.host);
}

/// Until the run's time is up, it is stopped (Ctrl-C), or a process dies: a process that
/// ends with code 0 is done (an fsm_node whose machine stopped, a node the simulated clock
/// stopped at its end), one whose scenario says restart is started again, any other ends the run
/// with the end of its log. Prints `progress()` every second on a terminal, every 10 s else.
/// Whether every process planned on `host` drives a car (its simulator, bridge, camera, marker
/// finder, state machine): losing that host loses those cars, not the run.
bool carries_only_cars(const std::vector<ProcessPlan>& plan, const std::string& host)
{
    return std::all_of(plan.begin(), plan.end(), [&](const ProcessPlan& p) { return p.host != host || p.vehicle_id != 0; });
}

void supervise(ProcessGroup& group, std::set<std::string>& died, RunResult& result, const LabClock& clock,
               const std::function<std::string()>& progress, const RunOptions& o, const fs::path& dir, const std::vector<ProcessPlan>& plan)
{
    const bool tty = o.progress && ::isatty(::fileno(o.progress));
    auto last_progress = Clock::now();
    while (result.error.empty()) {
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
        if (o.stop()) {
            result.interrupted = true;
            break;
        }
        for (const auto& e : group.poll()) {
            if (e.end.ok()) continue;
            if (e.restarted) {
                if (o.progress) std::fprintf(o.progress, "cpm lab run: %s %s; restarting it (restart: true)\n", e.name.c_str(), e.end.describe().c_str());
                continue;
            }
            died.insert(e.name);
            mark_host_lost(result.hosts, e);
            if (e.host_lost && carries_only_cars(plan, e.host)) {  // its cars are lost; the others drive on
                if (o.progress) std::fprintf(o.progress, "cpm lab run: %s %s; the run goes on without it\n", e.name.c_str(), e.describe().c_str());
                continue;
            }
            if (result.error.empty()) {
                result.error = e.name + " " + e.describe() + " during the run; the end of its log (" + (dir / (e.name + ".log")).string() +
                               "):\n" + group.tail(e.name);
            }
        }
        if (!result.error.empty()) break;
        if (clock.ended(result.error)) {
            // A node or car the clock waited for in vain: what its log says (it may be waiting itself).
            for (const auto& p : plan) {
                const bool named = result.error.find("'" + p.name + "'") != std::string::npos ||
                                   (!p.timer.empty() && result.error.find("'" + p.timer + "'") != std::string::npos);
                if (!named) continue;
                result.error += "\n" + p.name + "'s log (" + (dir / (p.name + ".log")).string() + ") ends:\n" + group.tail(p.name, 5);
            }
            break;
        }
        if (o.progress && Clock::now() - last_progress >= std::chrono::seconds(tty ? 1 : 10)) {
            last_progress = Clock::now();
            std::fprintf(o.progress, tty ? "\r%s   " : "%s\n", progress().c_str());
            std::fflush(o.progress);
        }
    }
    if (tty) std::fprintf(o.progress, "\n");
}

/// The node ids of every planned process's timers.
std::vector<std::string> timers_of(const std::vector<ProcessPlan>& plan)
{
    std::vector<std::string> timers;
    for (const auto& p : plan) {
        std::stringstream list(p.timer);
        for (std::string t; std::getline(list, t, ',');) timers.push_back(t);
    }
    return timers;
}

/// Each car of the run with the processes that serve it (a process of several cars serves its first).
std::map<int, std::vector<std::string>> cars_of(const Scenario& s, const std::vector<ProcessPlan>& plan)
{
    std::map<int, std::vector<std::string>> out;
    for (const auto& v : s.vehicles) out[v.id];
    for (const auto& p : plan) {
        if (out.count(p.vehicle_id)) out[p.vehicle_id].push_back(p.name);
    }
    return out;
}

/// The timers that a run in real time waits for before it starts the lab a second ahead: those
/// of the nodes that plan for the cars (central routing, the controllers' middlewares).
std::vector<std::string> planners_of(const Scenario& s)
{
    std::vector<std::string> out;
    if (s.routing.enabled) out.push_back(timer_ids::central_routing);
    for (const auto& c : s.controllers) out.push_back(timer_ids::hlc_middleware(c.name));
    return out;
}

/// Whether another cpm lab run on this host holds the domain (its lock file is locked).
bool held_by_another_run(int domain)
{
    const int fd = ::open(run_lock_path(domain).c_str(), O_RDWR | O_CLOEXEC);
    if (fd < 0) return false;
    const bool held = ::flock(fd, LOCK_EX | LOCK_NB) != 0;
    ::close(fd);
    return held;
}

/// Each controller's domain claimed as the run's own is (no other run, nobody on it), all at once.
std::vector<std::unique_ptr<DomainClaim>> claim_controller_domains(const Scenario& s, const RunSettings& settings)
{
    const auto domains = controller_domains(s, settings);
    std::vector<std::future<std::unique_ptr<DomainClaim>>> claims;
    for (const auto& [name, domain] : domains) {
        // One on another host has its domain there, this host only: nothing to see from here.
        const auto spec = std::find_if(s.controllers.begin(), s.controllers.end(), [&](const ControllerSpec& c) { return c.name == name; });
        if (const HostSpec* h = spec == s.controllers.end() ? nullptr : s.host(spec->host); h && !h->ssh.empty()) continue;
        claims.push_back(std::async(std::launch::async, [&s, name = name, domain = domain] {
            ParticipantOptions po;  // this host only, as the controller's and its middleware's
            po.domain_id = domain;
            po.name = "cpm_lab_run";
            return std::make_unique<DomainClaim>(domain, po, s, "controller " + name + "'s domain");
        }));
    }
    std::vector<std::unique_ptr<DomainClaim>> out;
    std::string errors;
    for (auto& c : claims) {
        try {
            out.push_back(c.get());
        } catch (const std::exception& e) {
            errors += (errors.empty() ? "" : "; ") + std::string(e.what());
        }
    }
    if (!errors.empty()) throw cpm::Error(errors);
    return out;
}

/// The history first (after a discovery server, which it needs), so that the recording holds the
/// run from its first sample, then the rest. An error message when the history does not answer
/// ("" when all started).
std::string start_processes(ProcessGroup& group, const Scenario& s, const std::vector<ProcessPlan>& plan, const fs::path& dir,
                            const RunSettings& settings, const std::string& qos, HistoryClient& history, const std::function<bool()>& stop)
{
    const auto history_at = std::find_if(plan.begin(), plan.end(), [](const ProcessPlan& p) { return p.name == "cpm_history"; });
    if (history_at == plan.end()) throw cpm::Error("a run's plan without cpm_history");
    const size_t first = size_t(history_at - plan.begin()) + 1;
    const std::string& history_name = history_at->name;
    for (size_t i = 0; i < first; ++i) (void)group.start(spec_of(plan[i], dir, settings, qos, s));
    bool up = false;
    const auto deadline = Clock::now() + std::chrono::seconds(15);
    while (!up && Clock::now() < deadline && !stop() && group.find(history_name)->running()) {
        try {
            up = history.request(HistoryClient::make(history::Kind::list, "", "")).status() == "ok";
        } catch (const std::exception&) {
        }
    }
    if (!up) return "the history service did not answer within 15 s; the end of its log:\n" + group.tail(history_name);
    for (size_t i = first; i < plan.size(); ++i) (void)group.start(spec_of(plan[i], dir, settings, qos, s));
    return "";
}

/// The run's claim on its folder: made, the scenario copied in; a secured lab's nodes issued
/// (each allowed the topics its process uses, for two days; a node of the same name is an
/// earlier run's whose folder had the same name: issued again). The run's own security folder.
std::string prepare_folder(const Scenario& s, const RunSettings& settings, const std::vector<ProcessPlan>& plan, const fs::path& dir)
{
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec) throw cpm::Error("cannot make the run's folder " + dir.string() + ": " + ec.message());
    fs::copy_file(s.file, dir / "scenario.yaml", fs::copy_options::overwrite_existing, ec);
    if (s.security.empty()) return "";
    auto issue = [&](const std::string& name, const ProcessPlan& p) {
        fs::remove_all(fs::path(s.security) / "nodes" / name);
        return security::add_node(s.security, name, {p.publish, p.subscribe, 2});
    };
    const std::string own = issue(security_node_name(settings, "cpm_lab_run"), lab_run_process());
    for (const auto& p : plan) (void)issue(fs::path(p.security_node).filename().string(), p);
    return own;
}

/// Every planned process's end for the summary: failed when it died during the run or did not
/// end cleanly on the run's stop (SIGINT's exit code 0, or ended by SIGINT/SIGTERM).
nlohmann::json process_ends(const std::vector<ProcessPlan>& plan, const ProcessGroup& group, const std::set<std::string>& died,
                            RunResult& result)
{
    nlohmann::json processes = nlohmann::json::array();
    for (const auto& p : plan) {
        const auto end = group.end_of(p.name);
        const bool lost = std::any_of(result.hosts.begin(), result.hosts.end(), [&](const RunResult::Host& h) { return h.lost && h.name == p.host; });
        ProcessEnd e{p.name, lost && end && end->code == 255 ? "lost with host " + p.host : end ? end->describe() : "never started"};
        const bool clean = end && (end->ok() || end->signal == SIGINT || end->signal == SIGTERM);
        e.failed = died.count(p.name) > 0 || (end && !clean);
        e.restarts = group.restarts_of(p.name);
        if (e.failed) e.last_lines = group.tail(p.name);
        processes.push_back({{"name", e.name}, {"argv", p.argv}, {"end", e.how}, {"failed", e.failed}, {"restarts", e.restarts},
                             {"log", p.name + ".log"}, {"host", p.host}});
        result.processes.push_back(e);
    }
    return processes;
}

/// summary.json in the run's folder: the run, its processes, and the history's own counts (the
/// last JSON line of its log).
nlohmann::json hosts_json(const std::vector<RunResult::Host>& hosts)
{
    nlohmann::json out = nlohmann::json::array();
    for (const auto& h : hosts) {
        out.push_back({{"name", h.name}, {"address", h.address}, {"clock_offset_ns", h.clock_offset_ns}, {"rtt_ns", h.rtt_ns}, {"lost", h.lost}});
    }
    return out;
}

/// Each controller's figures as its middleware counted them (the last JSON line of its log):
/// periods, answered and unanswered ones, response times, forwarded and refused commands.
nlohmann::json controllers_json(const Scenario& s, const RunSettings& settings)
{
    nlohmann::json out = nlohmann::json::array();
    for (const auto& c : s.controllers) {
        nlohmann::json figures = last_json((fs::path(settings.run_dir) / ("hlc_" + c.name + ".log")).string());
        if (!figures.is_object()) figures = {{"controller", c.name}, {"error", "its middleware left no figures (see hlc_" + c.name + ".log)"}};
        out.push_back(figures);
    }
    return out;
}

/// The recording's block of the summary: the history's final counts of what reached the file,
/// and of what never reached the history (in all and per topic).
nlohmann::json recording_of(const nlohmann::json& recorded)
{
    nlohmann::json recording = recorded.contains("recording") ? recorded["recording"] : nlohmann::json();
    if (!recording.is_object()) return recording;
    recording["lost"] = recorded.value("lost", uint64_t(0));
    recording["lost_by_topic"] = recorded.value("lost_by_topic", nlohmann::json::object());
    return recording;
}

void write_summary(const Scenario& s, const RunSettings& settings, const std::string& qos, const RunResult& result,
                   const nlohmann::json& processes, const RunWatch& watch, const nlohmann::json& recorded)
{
    nlohmann::json summary{{"name", s.name},
                           {"scenario", fs::absolute(s.file).string()},
                           {"time", settings.time == TimeMode::simulated ? "simulated" : "real"},
                           {"domain", settings.domain},
                           {"duration_s", double(settings.duration_ns) / 1e9},  // not * 1e-9: 15.000000000000002
                           {"lab_time_s", double(result.lab_time_ns) / 1e9},
                           {"real_s", result.real_seconds},
                           {"clock_real_s", result.clock_seconds},
                           {"ok", result.ok},
                           {"interrupted", result.interrupted},
                           {"error", result.error},
                           {"vehicles", s.vehicles.size()},
                           {"world", s.world},
                           {"lanes", s.lanes},
                           {"processes", processes},
                           {"missed_deadlines", watch.missed()},
                           // The recording's own final count; the history's last status while it lasts.
                           {"samples_recorded", recorded.contains("recording") ? recorded["recording"].value("written", watch.recorded())
                                                                               : watch.recorded()},
                           {"qos", qos.empty() ? nlohmann::json::object() : nlohmann::json::parse(qos)},
                           {"recording", recording_of(recorded)},
                           {"hosts", hosts_json(result.hosts)},
                           {"controllers", controllers_json(s, settings)}};
    std::ofstream(fs::path(settings.run_dir) / "summary.json") << summary.dump(2) << "\n";
}

/// The run's settings and folder (fresh: a folder that holds anything is refused).
RunSettings settings_of(const Scenario& s, const RunOptions& o)
{
    RunSettings settings;
    settings.bin_dir = o.bin_dir.empty() ? cpm::executable_dir() : o.bin_dir;
    settings.domain = o.domain.value_or(s.domain.value_or(ParticipantOptions::from_init().domain_id));
    settings.time = o.time.value_or(s.time);
    // Not on the simulated clock, unless said (--dds_shared_memory, CPM_SHARED_MEMORY): Fast DDS
    // 2.9 sends a reader on the same host every sample over shared memory and over UDP loopback
    // both, and a simulated step waits for every one of them (the 8-car intersection ran 1.2-1.3x
    // faster on UDP alone, with the same recording). In real time the second path stays: a reader
    // stalled past shared memory's health check (200 ms) loses what was pushed into its port, a
    // UDP socket's buffer keeps it.
    const InitSettings init = init_settings();
    settings.shared_memory = init.shared_memory_chosen ? init.shared_memory : settings.time != TimeMode::simulated;
    settings.duration_ns = o.duration_ns.value_or(s.duration_ns);
    const fs::path dir = fs::absolute(o.out_dir.empty() ? fs::path("runs") / (s.name + "-" + utc_now_compact()) : fs::path(o.out_dir));
    std::error_code ec;
    if (fs::exists(dir, ec) && !fs::is_empty(dir, ec)) throw cpm::Error("the run's folder " + dir.string() + " exists and is not empty");
    settings.run_dir = dir.string();
    return settings;
}

/// The run's own participant: its domain, shared memory with the processes on this host as the
/// run's processes have it, and across hosts this host's address with the
/// others as peers.
ParticipantOptions participant_options(const Scenario& s, const RunSettings& settings)
{
    ParticipantOptions po = ParticipantOptions::from_init();
    po.domain_id = settings.domain;
    po.name = "cpm_lab_run";
    po.shared_memory = settings.shared_memory;
    if (const HostSpec* here = s.local_host()) {
        po.interfaces = {here->address};
        if (s.discovery_server) {
            po.discovery_server = s.discovery_server_locator();
            return po;
        }
        for (const auto& h : s.hosts) {
            if (h.name != here->name) po.initial_peers.push_back(h.address);
        }
    }
    return po;
}

/// The end, in order: every car told to stop, the timers stopped, then the processes that
/// command the cars, the cars, and the history last (it closes the recording). The stop is
/// stamped on the run's one clock: lab time in a simulated run, as every other sample. A host
/// that ssh finds lost only now (cut off in the run's last seconds) is lost all the same.
void stop_in_order(Writer<StopRequest>& stops, LabClock& clock, ProcessGroup& group, const Scenario& s, const RunSettings& settings,
                   const std::set<std::string>& died, RunResult& result, const RunOptions& o)
{
    StopRequest all;
    all.vehicle_id(0);
    cpm::stamp_message(all, clock.simulated() ? clock.now() : cpm::get_time_ns(), 0);
    (void)stops.write(all);
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    clock.stop();
    for (const auto& e : group.stop_all()) {
        if (!e.host_lost || died.count(e.name)) continue;  // one lost during the run was told then
        mark_host_lost(result.hosts, e);
        if (o.progress) std::fprintf(o.progress, "cpm lab run: %s %s while the run stopped\n", e.name.c_str(), e.describe().c_str());
    }
    remove_from_hosts(s, settings);
}

}  // namespace

RunResult run_lab(const Scenario& s, const RunOptions& o)
{
    RunSettings settings = settings_of(s, o);
    settings.controller_domains = controller_domains(s, settings, held_by_another_run);
    const fs::path dir = settings.run_dir;
    const auto plan = plan_run(s, settings);      // names a missing program before anything starts
    const SharedConnections connections(s, settings);
    // A host that cannot take part is named before anything starts; checked while the domain
    // is claimed (its 1.5 s of listening).
    auto checking = std::async(std::launch::async, [&] { return check_hosts(s, settings); });
    // Every process, this one too, makes its readers and writers with the scenario's QoS.
    const std::string qos = s.qos.empty() ? "" : to_json(s.qos);
    if (!qos.empty()) ::setenv(kQosOverridesVariable, qos.c_str(), 1);
    ParticipantOptions po = participant_options(s, settings);
    auto controller_claims = std::async(std::launch::async, [&] { return claim_controller_domains(s, settings); });
    const DomainClaim claim(settings.domain, po, s);
    const auto controller_domains_claimed = controller_claims.get();
    const auto hosts = checking.get();
    po.security = prepare_folder(s, settings, plan, dir);  // a secured lab's nodes issued, then copied to their hosts
    copy_to_hosts(s, plan, settings);

    RunResult result{.dir = dir.string(), .hosts = hosts};
    const auto t0 = Clock::now();
    RecorderGate recorder(s);  // told of every endpoint as long as the participant lives
    po.on_discovery = [&recorder](const DiscoveryEvent& e) { recorder.on_discovery(e); };
    Participant participant(po);
    Writer<StopRequest> stops(participant, topics::stop_request.name, topics::stop_request.writer);
    HistoryClient history(participant, std::chrono::milliseconds(2000));
    RunWatch watch(participant);
    LabClock clock(participant, settings, s.timeouts, [&] { recorder.wait(std::chrono::seconds(10), o.progress); }, o.progress);
    ProcessGroup group;          // every process of the run, stopped in order on every way out
    std::set<std::string> died;  // ended badly while the run went on

    result.error = start_processes(group, s, plan, dir, settings, qos, history, o.stop);
    if (o.progress) {
        std::fprintf(o.progress, "cpm lab run: %s: %zu processes on domain %d%s, logs and recording in %s\n", s.name.c_str(), plan.size(),
                     settings.domain, settings.shared_memory ? "" : " (UDP only, no shared memory)", dir.c_str());
        if (const HostSpec* there = s.host(s.monitor_host); s.monitor_port && there && !there->ssh.empty()) {
            std::fprintf(o.progress, "cpm lab run: the monitor serves on 127.0.0.1:%d on host %s (there, or here through ssh -L %d:127.0.0.1:%d %s)\n",
                         *s.monitor_port, there->name.c_str(), *s.monitor_port, *s.monitor_port, there->ssh.c_str());
        } else if (s.monitor_port) {
            std::fprintf(o.progress, "cpm lab run: watch it live at http://127.0.0.1:%d/ (cpm monitor, while the run lasts)\n", *s.monitor_port);
        }
    }
    if (result.error.empty()) clock.start(timers_of(plan), planners_of(s), cars_of(s, plan));
    supervise(group, died, result, clock, [&] {
        const double real = std::chrono::duration<double>(Clock::now() - t0).count();
        const std::string waiting = clock.waiting_for();
        const std::string note = clock.simulated()   ? " (simulated, " + std::to_string(int(real)) + " s real)"
                                 : waiting.empty() ? ""
                                                   : " (waiting for " + waiting + ")";
        char line[320];
        std::snprintf(line, sizeof line, "lab time %.1f / %.1f s%s, %zu car(s), %llu missed deadline(s), %llu samples recorded",
                      double(clock.now()) * 1e-9, double(settings.duration_ns) * 1e-9, note.c_str(), s.vehicles.size(),
                      (unsigned long long)watch.missed(), (unsigned long long)watch.recorded());
        return std::string(line);
    }, o, dir, plan);
    result.lab_time_ns = clock.now();
    result.clock_seconds = clock.stepped_seconds();
    stop_in_order(stops, clock, group, s, settings, died, result, o);
    result.real_seconds = std::chrono::duration<double>(Clock::now() - t0).count();

    const nlohmann::json processes = process_ends(plan, group, died, result);
    result.ok = result.error.empty() && !result.interrupted &&
                std::none_of(result.processes.begin(), result.processes.end(), [](const ProcessEnd& e) { return e.failed; }) &&
                std::none_of(result.hosts.begin(), result.hosts.end(), [](const RunResult::Host& h) { return h.lost; });
    const auto recorded = last_json((dir / "cpm_history.log").string());
    result.recording_lost_by_topic = recording_lost_by_topic(recording_of(recorded));
    write_summary(s, settings, qos, result, processes, watch, recorded);
    return result;
}

}  // namespace cpm::lab
