#include <cpm/monitor/Monitor.hpp>

#include "WebAssets.hpp"

#include <cpm/AsyncReader.hpp>
#include <cpm/Bookmark.hpp>
#include <cpm/Error.hpp>
#include <cpm/Logging.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/routing/LaneGraph.hpp>
#include <cpm/rtdb/TopicProbe.hpp>
#include <cpm/stamp_message.hpp>
#include <cpm/topics.hpp>

#include <Bookmark.h>
#include <StopRequest.h>

#include <httplib.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <condition_variable>
#include <cstring>
#include <thread>

namespace cpm::monitor {
namespace {

using Clock = std::chrono::steady_clock;

nlohmann::json world_json(const std::optional<vehicle::World>& world, const std::optional<routing::LaneGraph>& lanes)
{
    nlohmann::json walls = nlohmann::json::array(), markers = nlohmann::json::array(), gates = nlohmann::json::array(),
                   edges = nlohmann::json::array();
    if (world) {
        for (const auto& w : world->walls()) walls.push_back({w.x1, w.y1, w.x2, w.y2});
        for (const auto& m : world->markers()) markers.push_back({{"id", m.id}, {"x", m.x}, {"y", m.y}, {"yaw", m.yaw}, {"size", m.size}});
        for (const auto& g : world->gates()) gates.push_back({{"left", g.left}, {"right", g.right}});
    }
    if (lanes) {
        for (const auto& e : lanes->edges) {
            nlohmann::json points = nlohmann::json::array();
            for (const auto& p : e.points) points.push_back({p.x(), p.y()});
            edges.push_back(std::move(points));
        }
    }
    return {{"walls", walls}, {"markers", markers}, {"gates", gates}, {"lanes", edges}, {"lane_width", lanes ? lanes->lane_width : 0.0}};
}

void reply_json(httplib::Response& res, int status, const nlohmann::json& body)
{
    res.status = status;
    res.set_header("Cache-Control", "no-store");
    res.set_content(body.dump(), "application/json");
}

void reply_error(httplib::Response& res, int status, const std::string& message) { reply_json(res, status, {{"error", message}}); }

/// A GET endpoint takes no parameters: one given is a malformed request, answered 400.
bool no_parameters(const httplib::Request& req, httplib::Response& res)
{
    if (req.params.empty()) return true;
    reply_error(res, 400, req.path + " takes no parameters; got '" + req.params.begin()->first + "'");
    return false;
}

}  // namespace

// Asked of the system itself: httplib says only "no".
std::string listen_problem(const std::string& bind, int port)
{
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(uint16_t(port));
    if (inet_pton(AF_INET, bind.c_str(), &a.sin_addr) != 1) return "'" + bind + "' is not an IPv4 address";
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    if (fd < 0) return std::strerror(errno);
    const int one = 1;
    ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    std::string why;
    if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
        why = errno == EADDRINUSE      ? "the port is in use by another program"
              : errno == EADDRNOTAVAIL ? "the address is not one of this host's"
              : errno == EACCES        ? "ports below 1024 need root"
                                       : std::strerror(errno);
    }
    ::close(fd);
    return why;
}

std::string bind_warning(const std::string& bind, bool allow_stop)
{
    if (bind == "127.0.0.1" || bind == "localhost" || bind == "::1") return {};
    return "cpm monitor: warning: listening on " + bind + ": anyone who can reach this host on that network can watch the lab" +
           (allow_stop ? " and stop its cars (--allow-stop)" : "");
}

struct Monitor::Impl
{
    MonitorOptions options;
    Participant& participant;
    LiveState state;
    std::string world;  ///< /api/world, made once
    httplib::Server server;
    int port = 0;

    // The newest snapshot for the watchers, and its number.
    mutable std::mutex mutex;
    std::condition_variable published;  ///< a new snapshot, or stopping
    std::condition_variable changed;    ///< a sample came in (wakes the snapshot thread)
    std::condition_variable ended;      ///< stopping (wakes the housekeeping thread)
    std::shared_ptr<const std::string> latest;
    uint64_t sequence = 0;
    bool stopping = false;
    bool dirty = false;  ///< samples came in since the last snapshot
    bool idle = false;   ///< the snapshot thread waits for samples (not out the gap)

    std::atomic<uint64_t> sent{0}, skipped{0}, stops_sent{0};
    std::atomic<size_t> watchers{0};

    std::unique_ptr<Writer<StopRequest>> stops;
    std::unique_ptr<Writer<Bookmark>> marks;
    std::unique_ptr<rtdb::TopicProbe> probe;
    std::vector<std::shared_ptr<void>> readers;
    std::thread listener, snapshots, housekeeping;

    Impl(Participant& p, MonitorOptions o, std::optional<vehicle::World> w, std::optional<routing::LaneGraph> lanes)
        : options(std::move(o)), participant(p), state(w), world(world_json(w, lanes).dump())
    {
    }

    /// A sample came in. Wakes the snapshot thread only when it is idle: while it waits out the
    /// gap between two snapshots, a wake-up per sample would only cost a context switch.
    void touched()
    {
        bool wake = false;
        {
            std::lock_guard lock(mutex);
            dirty = true;
            wake = idle;
        }
        if (wake) changed.notify_one();
    }

    template <class T, class Feed>
    void read(const TopicSpec& topic, Feed feed)
    {
        auto reader = std::make_shared<AsyncReader<T>>(
            [this, name = std::string(topic.name), feed](std::vector<T>& batch) {
                const uint64_t now = get_time_ns();
                state.count(name, batch.size(), now);
                for (const auto& s : batch) (state.*feed)(s, now);
                touched();
            },
            participant, topic.name, topic.reader);
        readers.push_back(reader);
    }

    /// Makes a snapshot when samples came in (at most max_update_hz), and at least every 250 ms
    /// so that ages and staleness move on when nothing arrives.
    void make_snapshots()
    {
        const auto min_gap = std::chrono::duration<double>(1.0 / std::max(1.0, options.max_update_hz));
        auto last = Clock::now() - std::chrono::seconds(1);
        std::unique_lock lock(mutex);
        while (!stopping) {
            idle = true;
            changed.wait_for(lock, std::chrono::milliseconds(250), [&] { return stopping || dirty; });
            idle = false;
            if (stopping) break;
            const auto wait = last + std::chrono::duration_cast<Clock::duration>(min_gap) - Clock::now();
            if (wait > Clock::duration::zero()) {
                changed.wait_for(lock, wait, [&] { return stopping; });
                if (stopping) break;
            }
            dirty = false;
            lock.unlock();
            nlohmann::json snap = state.snapshot(get_time_ns());
            snap["allow_stop"] = options.allow_stop;
            auto message = std::make_shared<const std::string>("data: " + snap.dump() + "\n\n");
            lock.lock();
            latest = std::move(message);
            ++sequence;
            last = Clock::now();
            published.notify_all();
        }
        published.notify_all();
    }

    /// Once a second: is `cpm play` on the domain (a replay) or not (a live lab)?
    void keep_house()
    {
        std::unique_lock lock(mutex);
        while (!stopping) {
            lock.unlock();
            bool replay = false;
            std::vector<std::string> observers;
            try {
                for (const auto& name : probe->participants()) replay = replay || name.rfind("cpm_play", 0) == 0;
                for (const auto& t : probe->topics()) {
                    if (t.name != topics::vehicle_observation.name) continue;
                    for (const auto& w : t.writers) observers.push_back(w.participant);
                }
            } catch (const std::exception&) {
            }
            state.set_source(replay ? "replay" : "live");
            state.set_observation_writers(std::move(observers));
            lock.lock();
            ended.wait_for(lock, std::chrono::seconds(1), [&] { return stopping; });
        }
    }

    void stream(httplib::Response& res)
    {
        if (watchers.load() >= options.max_watchers) {
            reply_error(res, 503, "too many watchers (" + std::to_string(options.max_watchers) + "); close a page and try again");
            return;
        }
        ++watchers;
        res.set_header("Cache-Control", "no-store");
        auto last = std::make_shared<uint64_t>(0);
        res.set_chunked_content_provider(
            "text/event-stream",
            [this, last](size_t, httplib::DataSink& sink) {
                std::shared_ptr<const std::string> message;
                {
                    std::unique_lock lock(mutex);
                    published.wait_for(lock, std::chrono::seconds(1), [&] { return stopping || (latest && sequence != *last); });
                    if (stopping) return false;
                    if (latest && sequence != *last) {
                        if (*last != 0) skipped += sequence - *last - 1;
                        *last = sequence;
                        message = latest;
                    }
                }
                static const std::string keepalive = ": keepalive\n\n";  // finds a watcher that left
                const std::string& text = message ? *message : keepalive;
                if (!sink.write(text.data(), text.size())) return false;
                if (message) ++sent;
                return true;
            },
            [this](bool) { --watchers; });
    }

    /// The request's JSON body; false (and the reply an error) when it is not one. Only a body
    /// sent as application/json: another site's page cannot send one without the browser asking
    /// this server first (CORS), which it never allows.
    static bool json_body(const httplib::Request& req, httplib::Response& res, nlohmann::json& body)
    {
        if (req.get_header_value("Content-Type").rfind("application/json", 0) != 0) {
            reply_error(res, 415, "send the body as Content-Type: application/json");
            return false;
        }
        try {
            body = nlohmann::json::parse(req.body);
        } catch (const nlohmann::json::exception& e) {
            reply_error(res, 400, std::string("the body is not JSON: ") + e.what());
            return false;
        }
        return true;
    }

    void stop_request(const httplib::Request& req, httplib::Response& res)
    {
        if (!options.allow_stop) {
            reply_error(res, 403, "stopping cars is off in this monitor; start it with --allow-stop");
            return;
        }
        nlohmann::json body;
        if (!json_body(req, res, body)) return;
        if (!body.is_object() || !body.contains("vehicle_id") || !body["vehicle_id"].is_number_integer()) {
            reply_error(res, 400, "the body must be {\"vehicle_id\": N} with N 1..255, or 0 for every car");
            return;
        }
        const auto id = body["vehicle_id"].get<int64_t>();
        if (id < 0 || id > 255) {
            reply_error(res, 400, "$.vehicle_id: " + std::to_string(id) + " is out of range (1..255, or 0 for every car)");
            return;
        }
        if (id != 0) {
            const auto seen = state.car_ids();
            if (std::find(seen.begin(), seen.end(), uint8_t(id)) == seen.end()) {
                std::string list;
                for (auto c : seen) list += (list.empty() ? "" : ", ") + std::to_string(c);
                reply_error(res, 404, "$.vehicle_id: no car " + std::to_string(id) + " in this lab (cars: " + (list.empty() ? "none yet" : list) +
                                          "; 0 stops every car)");
                return;
            }
        }
        StopRequest s;
        s.vehicle_id(uint8_t(id));
        stamp_message(s, get_time_ns(), 0);
        if (!stops->write(s)) {
            reply_error(res, 500, "the StopRequest could not be written");
            return;
        }
        ++stops_sent;
        const std::string who = id == 0 ? "every car" : "car " + std::to_string(id);
        Logging::instance().write(Severity::warn, "cpm monitor: stop requested for %s from %s", who.c_str(), req.remote_addr.c_str());
        reply_json(res, 200, {{"stopped", id}, {"message", "StopRequest sent to " + who}});
    }

    /// POST /api/mark {"text": "..."}: a bookmark of this moment, its source "monitor".
    void mark_request(const httplib::Request& req, httplib::Response& res)
    {
        nlohmann::json body;
        if (!json_body(req, res, body)) return;
        if (!body.is_object() || !body.contains("text") || !body["text"].is_string()) {
            reply_error(res, 400, "the body must be {\"text\": \"what happened\"}");
            return;
        }
        const std::string text = body["text"].get<std::string>();
        if (const std::string problem = bookmark_problem(text, "monitor"); !problem.empty()) {
            reply_error(res, 400, "$.text: " + problem);
            return;
        }
        if (marks->matched_subscriptions() == 0) {
            reply_error(res, 503, "nobody records bookmarks on this domain (no history service, no lab run); the mark is not made");
            return;
        }
        Bookmark b;
        b.text(text);
        b.source("monitor");
        const uint64_t now = get_time_ns();
        stamp_message(b, now, 0);
        if (!marks->write(b)) {
            reply_error(res, 500, "the Bookmark could not be written");
            return;
        }
        Logging::instance().write(Severity::info, "cpm monitor: marked '%s' from %s", text.c_str(), req.remote_addr.c_str());
        reply_json(res, 200, {{"marked_ns", now}, {"message", "marked: " + text}});
    }

    void routes()
    {
        server.new_task_queue = [n = options.max_watchers + 8] { return new httplib::ThreadPool(n); };
        // httplib's default also sets SO_REUSEPORT, with which a second monitor would share the
        // port silently instead of being told it is in use. A small send buffer bounds what the
        // kernel holds for a watcher that does not read (accepted sockets inherit it).
        server.set_socket_options([](int sock) {
            const int yes = 1, send_buffer = 64 * 1024;
            ::setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
            ::setsockopt(sock, SOL_SOCKET, SO_SNDBUF, &send_buffer, sizeof send_buffer);
        });
        server.set_write_timeout(options.write_timeout.count() / 1000, (options.write_timeout.count() % 1000) * 1000);
        for (const auto& asset : web_assets()) {
            const std::string path = asset.path == "/index.html" ? "/" : std::string(asset.path);
            server.Get(path, [asset](const httplib::Request&, httplib::Response& res) {
                res.set_header("Cache-Control", "no-store");
                res.set_content(std::string(asset.body), std::string(asset.content_type).c_str());
            });
        }
        server.Get("/api/state", [this](const httplib::Request& req, httplib::Response& res) {
            if (!no_parameters(req, res)) return;
            nlohmann::json snap = state.snapshot(get_time_ns());
            snap["allow_stop"] = options.allow_stop;
            reply_json(res, 200, snap);
        });
        server.Get("/api/world", [this](const httplib::Request& req, httplib::Response& res) {
            if (no_parameters(req, res)) res.set_content(world, "application/json");
        });
        server.Get("/api/plots", [this](const httplib::Request& req, httplib::Response& res) {
            if (no_parameters(req, res)) reply_json(res, 200, state.plots(get_time_ns()));
        });
        server.Get("/api/stream", [this](const httplib::Request& req, httplib::Response& res) {
            if (no_parameters(req, res)) stream(res);
        });
        server.Post("/api/stop", [this](const httplib::Request& req, httplib::Response& res) { stop_request(req, res); });
        server.Post("/api/mark", [this](const httplib::Request& req, httplib::Response& res) { mark_request(req, res); });
        // A path that exists answers another method with 405 and what it allows, not 404.
        auto not_allowed = [](const char* allow) {
            return [allow](const httplib::Request& req, httplib::Response& res) {
                res.set_header("Allow", allow);
                reply_error(res, 405, req.method + " " + req.path + ": not allowed here (" + allow + " is)");
            };
        };
        server.Get("/api/stop", not_allowed("POST"));
        server.Get("/api/mark", not_allowed("POST"));
        for (const char* path : {"/api/state", "/api/world", "/api/plots", "/api/stream", "/api/stop", "/api/mark"}) {
            const char* allow = std::string(path) == "/api/stop" || std::string(path) == "/api/mark" ? "POST" : "GET";
            if (std::string(allow) == "GET") server.Post(path, not_allowed(allow));
            server.Put(path, not_allowed(allow));
            server.Delete(path, not_allowed(allow));
            server.Patch(path, not_allowed(allow));
        }
        server.set_error_handler([](const httplib::Request& req, httplib::Response& res) {
            if (!res.body.empty()) return;
            if (res.status == 404) {
                reply_error(res, 404, "nothing at " + req.path + " (the page is at /, the API under /api/)");
            } else {
                reply_error(res, res.status, "bad request");
            }
        });
    }
};

Monitor::Monitor(Participant& participant, MonitorOptions options)
{
    std::optional<vehicle::World> world;
    if (!options.world.empty()) world = vehicle::World::load(options.world);
    std::optional<routing::LaneGraph> lanes;
    if (!options.lanes.empty()) lanes = routing::load_lane_graph_or_throw(options.lanes);
    impl_ = std::make_unique<Impl>(participant, options, std::move(world), std::move(lanes));
    Impl& m = *impl_;
    m.routes();
    if (options.port == 0) {
        m.port = m.server.bind_to_any_port(options.bind);
        if (m.port <= 0) throw Error("cpm monitor: cannot listen on " + options.bind + ": " + listen_problem(options.bind, 0));
    } else {
        if (!m.server.bind_to_port(options.bind, options.port)) {
            throw Error("cpm monitor: cannot listen on " + options.bind + ":" + std::to_string(options.port) + ": " +
                        listen_problem(options.bind, options.port) + " (choose another with --port)");
        }
        m.port = options.port;
    }
    if (options.allow_stop) m.stops = std::make_unique<Writer<StopRequest>>(participant, topics::stop_request.name, topics::stop_request.writer);
    m.marks = std::make_unique<Writer<Bookmark>>(participant, topics::bookmark.name, topics::bookmark.writer);
    m.read<VehicleState>(topics::vehicle_state, &LiveState::on_state);
    m.read<VehicleObservation>(topics::vehicle_observation, &LiveState::on_observation);
    m.read<RangeSensors>(topics::range_sensors, &LiveState::on_ranges);
    m.read<FsmStatus>(topics::fsm_status, &LiveState::on_fsm);
    m.read<ArucoMarkers>(topics::aruco_markers, &LiveState::on_markers);
    m.read<Log>(topics::log, &LiveState::on_log);
    m.read<HistoryStatus>(topics::history_status, &LiveState::on_history_status);
    ParticipantOptions probe_options = ParticipantOptions::from_init();
    probe_options.domain_id = participant.domain_id();
    probe_options.name = "cpm_monitor_probe";
    m.probe = std::make_unique<rtdb::TopicProbe>(probe_options);
    m.snapshots = std::thread([&m] { m.make_snapshots(); });
    m.housekeeping = std::thread([&m] { m.keep_house(); });
    m.listener = std::thread([&m] { m.server.listen_after_bind(); });
    // Until it runs, httplib's stop() would not reach it: wait, so that a Monitor made and
    // destroyed at once ends.
    for (int i = 0; i < 2000 && !m.server.is_running(); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(1));
}

Monitor::~Monitor()
{
    {
        std::lock_guard lock(impl_->mutex);
        impl_->stopping = true;
    }
    impl_->published.notify_all();
    impl_->changed.notify_all();
    impl_->ended.notify_all();
    impl_->server.stop();
    for (auto* t : {&impl_->listener, &impl_->snapshots, &impl_->housekeeping}) {
        if (t->joinable()) t->join();
    }
    impl_->readers.clear();
    // The writers go before the probe's participant: Fast DDS 2.9 tells the endpoints of the
    // process's other participants of a writer removed, and one just deleted crashes it there
    // (StatefulWriter::intraprocess_gap, seen about once in 80 runs).
    impl_->marks.reset();
    impl_->stops.reset();
    impl_->probe.reset();
}

int Monitor::port() const { return impl_->port; }

std::string Monitor::address() const { return "http://" + impl_->options.bind + ":" + std::to_string(impl_->port) + "/"; }

LiveState& Monitor::state() { return impl_->state; }

Monitor::Stats Monitor::stats() const
{
    Stats s;
    {
        std::lock_guard lock(impl_->mutex);
        s.snapshots = impl_->sequence;
    }
    s.sent = impl_->sent;
    s.skipped = impl_->skipped;
    s.watchers = impl_->watchers;
    s.stops_sent = impl_->stops_sent;
    return s;
}

}  // namespace cpm::monitor
