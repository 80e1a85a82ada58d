#pragma once
// cpm::lab — a lab scenario (scenarios/labs/*.yaml) read and checked, and the processes a run of
// it starts. The file's shape:
//
//   name: corridor-demo
//   domain: 7                       # optional; default from CPM_DOMAIN_ID or 0
//   time: real                      # real | simulated
//   duration: 30s
//   world: ../maps/corridor.json    # paths relative to this file
//   lanes: ../lanes/intersection.json
//   vehicles:
//     - id: 5
//       start: [0.0, -0.1, 0.0]     # x, y, yaw
//       camera: ../cameras/sim_640x480.yaml   # synthetic camera + aruco_node
//       fsm: ../fsm/corridor.json             # fsm_node for this car
//       restart: false              # restart its processes when they die (default: the run stops)
//       realtime: true              # its processes run with --realtime (or `required`: refuse without)
//   routing: {enabled: false, seed: 1, period: 400ms, restart: false, realtime: false}
//   qos: {vehicleState: {reliable: false, history_depth: 1}}
//   record: {topics: ["*"], exclude: ["cameraFrame"]}
//   parameters: ../params/lab.yaml  # served to every node (cpm param serve)
//   security: ../lab-sec            # a secured lab (a folder from `cpm security init`): each
//                                   # process runs as a node of its own, allowed the topics it uses
//   controllers:                    # users' high-level controllers (cpm::hlc), each with its
//     - program: ../controllers/platoon.py   # hlc_middleware; a program, a Python script, or the
//                                   # name of one of cpm's programs (hlc_platoon)
//       name: platoon               # default: the program's file name without extension
//       args: ["--gap", "1.0s"]     # then --vehicle_ids 1,2,… --dds_domain D [--simulated_time]
//       vehicles: [1, 2, 3, 4]      # the cars it drives (on the lanes, as with routing)
//       period: 100ms
//       domain: 40                  # the domain it shares with its middleware; default: chosen
//       host: car5                  # where it and its middleware run (default: the run's host)
//       realtime: true              # it and its middleware run with --realtime
//   monitor: 8080                   # cpm monitor on this port while the run lasts, or
//                                   # {port: 8080, allow_stop: true} for its stop buttons; off: none
//
// load_scenario reports every error at once, each with the file, line and YAML path
// ("corridor.yaml:12: vehicles[1].id: 5 is given twice (also vehicles[0])").
#include <cpm/Diagnostics.hpp>
#include <cpm/QosOverrides.hpp>
#include <cpm/Realtime.hpp>

#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace cpm::lab {

enum class TimeMode { real, simulated };

struct VehicleSpec
{
    int id = 0;
    double x = 0, y = 0, yaw = 0;
    std::string camera;  ///< absolute path, or empty
    std::string fsm;     ///< absolute path, or empty
    bool restart = false;
    std::string host;    ///< where its processes run (a name of `hosts:`); "" the run's own
    Realtime realtime = Realtime::off;  ///< --realtime for its processes (simulator, bridge, camera, aruco, fsm)
    bool avr = false;    ///< firmware: avr - the car's real firmware under firmware_hil instead of firmware_sim
};

/// A computer of the lab (`hosts:`): the address its participants use and how the run reaches it.
struct HostSpec
{
    std::string name;
    std::string address;  ///< IPv4: its processes' --dds_interface, the others' --dds_initial_peer
    std::string ssh;      ///< ssh's destination; "" for the host the run runs on
    std::string cpm;      ///< where cpm is installed there (its programs in cpm/bin)
};

struct RoutingSpec
{
    bool enabled = false;
    uint64_t seed = 1;
    uint64_t period_ns = 400'000'000ull;
    bool restart = false;
    std::string host;  ///< where central_routing runs; "" the run's own
    Realtime realtime = Realtime::off;
};

/// The lab's positioning system (`ips:`): an overhead camera (simulated: camera_sim --overhead)
/// and ips_node, which then writes every car's vehicleObservation; the simulators write their
/// truth to vehicleObservationTruth.
struct IpsSpec
{
    bool enabled = false;
    std::string camera;     ///< absolute path of the overhead camera's file (with its pose in the map)
    std::string world;      ///< absolute path of the map with roof_markers and floor_markers
    std::string host;       ///< where the camera and ips_node run; "" the run's own
    double rate_hz = 50;    ///< the camera's frame rate
    double noise = 0;       ///< the simulated camera's sensor noise (grey levels)
    int blur = 0;           ///< and blur (box, px)
};

/// A user's high-level controller and what it drives (`controllers:`).
struct ControllerSpec
{
    std::string name;               ///< unique in the run: its processes are controller_<name>, hlc_<name>
    std::string program;            ///< absolute path: an executable, or a Python script (.py); a bare name: cpm's program
    std::vector<std::string> args;  ///< given before the run's own flags; files beside the scenario by their full path
    std::vector<int> vehicles;      ///< the cars it drives
    uint64_t period_ns = 100'000'000;
    std::optional<int> domain;      ///< the controller's own domain; unset: the run chooses one
    std::string host;               ///< where it and its middleware run (a name of hosts:); "" the run's own
    Realtime realtime = Realtime::off;  ///< --realtime for it and its middleware
    bool python() const;
};

/// Per-topic QoS a run applies to every node (unset: each node's own choice); the run passes
/// them on in CPM_QOS_OVERRIDES.
using QosOverride = cpm::QosOverride;

struct RecordSpec
{
    std::vector<std::string> topics{"*"};  ///< `*` and `?` patterns
    std::vector<std::string> exclude;
};

/// `timeouts:` how long a run waits before it ends naming what it waited for.
struct Timeouts
{
    /// For its processes to come up: every timer to join the simulated clock; in real time every
    /// car's first state and the planners' readiness (over ssh on a busy host too).
    uint64_t start_ns = 30'000'000'000;
    /// Simulated time: for each node's tick of a step (a node that stalls mid-run).
    uint64_t step_ns = 10'000'000'000;
};

struct Scenario
{
    std::string file;  ///< as given
    std::string dir;   ///< the folder relative paths in it start from
    std::string name;
    std::optional<int> domain;
    TimeMode time = TimeMode::real;
    uint64_t duration_ns = 0;
    std::string world;  ///< absolute path
    std::string lanes;  ///< absolute path, or empty
    std::string parameters;  ///< absolute path of a parameter file (`cpm param serve`), or empty
    std::string security;    ///< absolute path of the lab's security folder (`cpm security init`), or empty
    std::vector<VehicleSpec> vehicles;
    RoutingSpec routing;
    IpsSpec ips;
    std::vector<ControllerSpec> controllers;
    /// The cars run in one simulator spread over the lanes (with routing or controllers).
    bool cars_on_lanes() const { return routing.enabled || !controllers.empty(); }
    std::map<std::string, QosOverride> qos;
    RecordSpec record;
    std::optional<int> monitor_port;  ///< cpm monitor on 127.0.0.1 at this port during the run
    bool monitor_allow_stop = false;
    std::string monitor_host;  ///< where the monitor runs; "" the run's own
    std::string history_host;  ///< where the history records; "" the run's own
    std::vector<HostSpec> hosts;  ///< empty: every process on the run's own host
    std::string ssh_config;       ///< an ssh config file for reaching the hosts (ssh -F), or empty
    uint64_t max_clock_offset_ns = 2'000'000;  ///< a host's clock further off refuses the run
    Timeouts timeouts;
    /// The port fast-discovery-server listens on (its default).
    static constexpr int kDiscoveryServerPort = 11811;
    /// `discovery: server`: every participant finds the others through fast-discovery-server,
    /// which the run starts on this host (a name of hosts:); false: unicast to every host (peers).
    bool discovery_server = false;
    std::string discovery_server_host;
    /// With discovery_server: the server's address:port every participant is pointed at.
    std::string discovery_server_locator() const;
    /// The host the run runs on (the one without ssh), or nullptr without hosts.
    const HostSpec* local_host() const;
    /// The host of that name ("": the run's own), or nullptr.
    const HostSpec* host(const std::string& name) const;
};

/// Every error of a scenario file, one "FILE:LINE: PATH: message" each.
class ScenarioError : public FileError
{
public:
    using FileError::FileError;
    std::vector<std::string> errors() const { return texts(); }
};

/// Reads and checks a scenario: unknown keys, wrong types and values, files that do not exist,
/// vehicle ids given twice, combinations a run cannot do. Throws ScenarioError with all of them.
Scenario load_scenario(const std::string& path);

/// One process a run starts.
struct ProcessPlan
{
    std::string name;               ///< unique in the run; its log is <name>.log
    std::vector<std::string> argv;  ///< argv[0]: the program's path
    bool restart = false;
    int stop_order = 0;             ///< stopped in rising order at the end (cars' controllers first)
    std::string timer;              ///< the node id of its timer for the lab clock, if it has one
    std::vector<std::string> publish;    ///< the topics it writes (patterns), beyond every process's own
    std::vector<std::string> subscribe;  ///< the topics it reads (patterns)
    std::string security_node;      ///< secured run: the node folder it runs as (--security), issued by the run
    std::string host;               ///< the host it runs on ("" the run's own); argv[0] is a path there
    int vehicle_id = 0;             ///< the car it drives or simulates (its first, for several); 0: none
    /// On another host: the files it reads, copied there before it starts (local path, path there).
    std::vector<std::pair<std::string, std::string>> copies;
};

struct RunSettings
{
    std::string bin_dir;      ///< where cpm's programs are
    std::string run_dir;      ///< the run's folder (recording.db goes there)
    int domain = 0;
    uint64_t duration_ns = 0; ///< the scenario's unless overridden
    TimeMode time = TimeMode::real;
    bool shared_memory = true; ///< the run's processes share memory on their host (not in simulated time, unless told)
    std::string ssh_shared_dir; ///< where ssh keeps the run's one connection per other host ("": none)
    /// Each controller's own domain (by name) where the scenario names none, as the run chose
    /// it (controller_domains()).
    std::map<std::string, int> controller_domains;
};

/// A secured run's node name for one of its processes ("cpm_lab_run" for the run itself): the
/// run's folder name and the process, so that every run has nodes of its own.
std::string security_node_name(const RunSettings& settings, const std::string& process);
/// The run's folder on another host (/tmp/cpm-runs/<the run folder's name>): the files its
/// processes read, copied there, and their serial links.
std::string remote_run_dir(const RunSettings& settings);
/// The topics `cpm lab run` itself uses: the stop requests and the clock's start it writes; the
/// log, the history's status and the timers' readiness it reads.
ProcessPlan lab_run_process();

/// The domain each controller of the run shares with its middleware (by name): its own
/// `domain:`, else the run's choice (settings.controller_domains), else the first after the run's
/// domain that neither the run nor another controller has and `unavailable` does not refuse.
std::map<std::string, int> controller_domains(const Scenario& s, const RunSettings& settings,
                                              const std::function<bool(int)>& unavailable = {});

/// The processes of a run, in the order they start: the history recording first, the parameter
/// server, the monitor, then the cars
/// (simulator and bridge), their cameras and aruco_nodes, routing, the controllers with their
/// middlewares, the fsm_nodes. Throws
/// ScenarioError naming every program that is missing from bin_dir.
std::vector<ProcessPlan> plan_run(const Scenario& s, const RunSettings& settings);

}  // namespace cpm::lab
