#pragma once
// The node ids of the timers of cpm's own nodes. On the lab's simulated clock `cpm lab clock`
// (and `cpm lab run`) waits until each named id says it is ready, so a node names its timer with
// one of these and every program that starts nodes and tells the clock whom to wait for (`cpm
// vehicle sim`, `cpm lab run`) names the same one.
#include <cstdint>
#include <string>

namespace cpm::timer_ids {

/// One firmware_sim process, named by the first of its vehicles.
inline std::string firmware_sim(int first_vehicle_id) { return "firmware_sim_" + std::to_string(first_vehicle_id); }
/// One vehicle_bridge process, named by the first of its vehicles.
inline std::string vehicle_bridge(int first_vehicle_id) { return "vehicle_bridge_" + std::to_string(first_vehicle_id); }
inline std::string camera_sim(int vehicle_id) { return "camera_sim_" + std::to_string(vehicle_id); }
inline std::string aruco_node(int vehicle_id) { return "aruco_node_" + std::to_string(vehicle_id); }
inline std::string fsm_node(int vehicle_id) { return "fsm_node_" + std::to_string(vehicle_id); }
inline constexpr const char* central_routing = "central_routing";
/// The history service recording a simulated run (cpm_history --simulated-clock): it holds the
/// clock back while the recorder has not yet received what the nodes wrote.
inline constexpr const char* history = "cpm_history";
/// The overhead positioning camera (camera_sim --overhead) and the positioning system (ips_node).
inline constexpr const char* ips_camera = "ips_camera";
inline constexpr const char* ips_node = "ips_node";
/// The middleware of one high-level controller, named by the controller.
inline std::string hlc_middleware(const std::string& controller) { return "hlc_middleware_" + controller; }

/// Where a car's and a camera's ticks fall in their period on the simulated clock. The car's
/// simulator and its bridge tick in one step, 1 ms into each period: the bridge answers the
/// state packet the simulator wrote in that step (it waits for it on the line), and whoever
/// ticks at the period's start (a state machine, a controller's middleware) reads the car of the
/// step before, never a sample still being written in its own step. A simulated camera renders
/// 1 ms later still (a quarter of its period at most), from the pose the simulator wrote the step
/// before. The recorder ticks in the cars' step too (one step less of its own), and so does
/// central_routing: it reads the cars' states as of a nanosecond before the step and makes its
/// plans valid a nanosecond after it, so the cars take them in their next step.
inline constexpr uint64_t kSimulatedCarOffset_ns = 1'000'000;
/// The lab time a node ticking at t in the cars' step reads the others' samples at on the
/// simulated clock: a nanosecond before its step, so a sample written in that step (whose arrival
/// races the tick) is never taken; what it writes there is valid a nanosecond after it.
inline constexpr uint64_t simulated_read_before_step(uint64_t t_ns) { return t_ns - 1; }
inline constexpr uint64_t simulated_camera_offset_ns(uint64_t period_ns) { return period_ns / 4 < 2'000'000 ? period_ns / 4 : 2'000'000; }

}  // namespace cpm::timer_ids
