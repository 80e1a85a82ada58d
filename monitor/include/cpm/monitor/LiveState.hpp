#pragma once
// cpm::monitor::LiveState — what `cpm monitor` shows, gathered from the lab's samples: every car's
// newest pose, state, ranges, FSM state and markers, the topics with their rates, the newest log
// lines, and 30 s of speed and clearance per car for the plots. No DDS and no HTTP here: the
// monitor's readers feed it, its server asks it for JSON. Thread-safe.
//
// Times: `now_ns` is when the monitor took the sample (cpm::get_time_ns). A car's age is measured
// from there, so a replay or a simulated lab (whose stamps are not this host's clock) is judged
// by what arrives, not by its stamps.
#include <cpm/vehicle/World.hpp>

#include <ArucoMarkers.h>
#include <FsmStatus.h>
#include <HistoryStatus.h>
#include <Log.h>
#include <RangeSensors.h>
#include <VehicleObservation.h>
#include <VehicleState.h>

#include <nlohmann/json.hpp>

#include <cstdint>
#include <deque>
#include <map>
#include <mutex>
#include <optional>
#include <string>

namespace cpm::monitor {

struct LiveOptions
{
    double stale_after_s = 1.0;    ///< a car whose newest sample is older is drawn as stale
    double plot_window_s = 30.0;   ///< how much of each car's speed and clearance is kept
    double plot_period_s = 0.1;    ///< one plot point per car at most this often
    double markers_for_s = 1.0;    ///< markers seen longer ago than this are not shown
    size_t log_lines = 20;         ///< the newest log lines in each snapshot
    double rate_window_s = 2.0;    ///< rates are counted over this long
};

class LiveState
{
public:
    explicit LiveState(std::optional<vehicle::World> world = std::nullopt, LiveOptions options = {});

    void on_state(const VehicleState& s, uint64_t now_ns);
    void on_observation(const VehicleObservation& o, uint64_t now_ns);
    void on_ranges(const RangeSensors& r, uint64_t now_ns);
    void on_fsm(const FsmStatus& f, uint64_t now_ns);
    void on_markers(const ArucoMarkers& m, uint64_t now_ns);
    void on_log(const Log& l, uint64_t now_ns);
    /// The history service's per-topic rates fill in topics the monitor does not read itself.
    void on_history_status(const HistoryStatus& h, uint64_t now_ns);
    /// `n` samples of `topic` arrived (for its rate).
    void count(const std::string& topic, size_t n, uint64_t now_ns);
    /// What feeds the lab: "live", or "replay" while `cpm play` is on the domain.
    void set_source(const std::string& source);
    /// The participants (node names) discovery shows writing vehicleObservation: a car placed by
    /// it is said to be placed by them (the positioning system, ips_node, or a simulator).
    void set_observation_writers(std::vector<std::string> names);

    /// `GET /api/state`: {"t_ns", "source", "vehicles": [...], "topics": [...], "log": [...]}.
    nlohmann::json snapshot(uint64_t now_ns) const;
    /// `GET /api/plots`: per car, the last 30 s of [seconds before now, speed, clearance].
    nlohmann::json plots(uint64_t now_ns) const;
    /// Rises with every sample taken in; a server sends a new snapshot only when it has risen.
    uint64_t version() const;
    /// The ids of the cars seen so far, in order.
    std::vector<uint8_t> car_ids() const;

private:
    struct PlotPoint
    {
        uint64_t at_ns;
        double speed, clearance;
    };
    struct Car
    {
        std::optional<VehicleState> state;
        uint64_t state_at_ns = 0;
        std::optional<Pose2D> observed;  ///< from vehicleObservation (ground truth or camera)
        uint64_t observed_at_ns = 0;
        uint64_t observed_stamp_ns = 0;  ///< its create_stamp
        std::optional<RangeSensors> ranges;
        std::optional<FsmStatus> fsm;
        std::optional<ArucoMarkers> markers;
        uint64_t markers_at_ns = 0;
        std::deque<PlotPoint> plot;
    };
    struct Topic
    {
        std::deque<uint64_t> arrivals;  ///< receive times within the rate window
        std::optional<double> history_rate_hz;
        uint64_t history_seen_ns = 0;
    };
    Car& car(uint8_t id);
    void add_plot_point(Car& c, uint64_t now_ns);
    double clearance(const Car& c, std::string* to) const;

    const std::optional<vehicle::World> world_;
    const LiveOptions options_;
    mutable std::mutex mutex_;
    std::map<uint8_t, Car> cars_;
    std::map<std::string, Topic> topics_;
    std::deque<nlohmann::json> log_;
    std::string source_ = "live";
    std::vector<std::string> observation_writers_;
    uint64_t version_ = 0;
};

}  // namespace cpm::monitor
