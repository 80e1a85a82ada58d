#pragma once
// cpm::monitor::Monitor — the lab live in a browser: joins the domain as an ordinary cpm
// participant, reads the cars' topics into a LiveState, and serves over HTTP (cpp-httplib):
//
//   GET  /               the page (map, cars, panels, plots, topics, log), from files built into cpm
//   GET  /api/state      the newest snapshot as JSON
//   GET  /api/stream     the same snapshots as server-sent events, at most max_update_hz
//   GET  /api/world      walls, markers, gates and lanes, for drawing the map
//   GET  /api/plots      each car's last 30 s of speed and clearance
//   POST /api/stop       {"vehicle_id": N} (0: every car) → a StopRequest; 403 unless allow_stop
//
// A watcher that reads slowly or not at all never slows the DDS side: each watcher is sent the
// newest snapshot when it can take one (those in between are dropped for it), and one that
// cannot take a snapshot for write_timeout is disconnected.
#include <cpm/Participant.hpp>
#include <cpm/monitor/LiveState.hpp>

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>

namespace cpm::monitor {

struct MonitorOptions
{
    int port = 8080;                  ///< 0: a free port (see Monitor::port())
    std::string bind = "127.0.0.1";   ///< the address to listen on
    std::string world;                ///< world file (walls, markers, gates) to draw, or empty
    std::string lanes;                ///< lane graph file to draw, or empty
    bool allow_stop = false;          ///< whether /api/stop may send StopRequests
    double max_update_hz = 60;        ///< snapshots to each watcher at most this often (above the cars' 50 Hz, so the two do not beat)
    size_t max_watchers = 32;         ///< streams at once; more are answered 503
    std::chrono::milliseconds write_timeout{2000};
};

/// Why `bind:port` cannot be listened on now ("the port is in use by another program", …), or
/// empty when it can.
std::string listen_problem(const std::string& bind, int port);

/// The warning for listening on `bind` when it is not this host alone, or empty.
std::string bind_warning(const std::string& bind, bool allow_stop);

class Monitor
{
public:
    /// Reads the world and lanes, joins the domain, starts listening. Throws cpm::Error naming
    /// the file (and JSON path) of a bad world or lane file, or the address and port that cannot
    /// be listened on (in use, not this host's).
    Monitor(Participant& participant, MonitorOptions options);
    ~Monitor();
    Monitor(const Monitor&) = delete;
    Monitor& operator=(const Monitor&) = delete;

    int port() const;
    std::string address() const;  ///< http://BIND:PORT/
    LiveState& state();

    struct Stats
    {
        uint64_t snapshots = 0;      ///< made for the watchers
        uint64_t sent = 0;           ///< snapshots written to watchers, all together
        uint64_t skipped = 0;        ///< snapshots a slow watcher never got (it got a newer one)
        size_t watchers = 0;         ///< streams open now
        uint64_t stops_sent = 0;
    };
    Stats stats() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm::monitor
