// hlc_platoon: a high-level controller (cpm::hlc) for cars on a ring of lanes. Every period it
// is given its cars' states and answers each with a trajectory along its lane: at the nominal
// speed, slower when the car ahead on the ring is closer than the time gap allows.
//
//   cpm lab run scenarios/labs/platoon.yaml          # runs it with its middleware and four cars
//
// It is an ordinary cpm program: cpm::init takes the domain the run gives it (the controller's
// own, shared with its hlc_middleware), and its plain Writer of vehicleCommandTrajectory reaches
// the middleware, which checks each command and forwards it to the cars.
#include <cpm/CommandLine.hpp>
#include <cpm/Logging.hpp>
#include <cpm/Writer.hpp>
#include <cpm/hlc/Communicator.hpp>
#include <cpm/init.hpp>
#include <cpm/routing/LaneGraph.hpp>
#include <cpm/stamp_message.hpp>
#include <cpm/topics.hpp>

#include <VehicleCommandTrajectory.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

namespace {

const char* kHelp =
    "usage: hlc_platoon --lanes RING.json --vehicle_ids 1,2,… [--speed 0.6] [--gap 1.0s] [--dds_domain N]\n"
    "\n"
    "Drives the listed cars around a lane graph that is one loop (scenarios/lanes/ring.json):\n"
    "each at --speed (m/s), but never closer to the car ahead than --gap of time at its speed\n"
    "plus 0.45 m. A cpm::hlc controller: run it with `cpm lab run` (controllers: in a scenario),\n"
    "which starts its middleware and gives it --vehicle_ids and --dds_domain.\n";

using cpm::routing::LaneGraph;

/// The loop's edges in driving order and where each begins along the loop.
struct Loop
{
    std::vector<size_t> order;
    std::map<size_t, double> start;  // edge -> its start along the loop
    double length = 0;

    explicit Loop(const LaneGraph& g)
    {
        size_t e = 0;
        do {
            start[e] = length;
            order.push_back(e);
            length += g.edges[e].length();
            if (g.successors[e].size() != 1) throw cpm::Error("hlc_platoon: the lane graph is not one loop (edge " + std::to_string(e) + ")");
            e = g.successors[e][0];
        } while (e != 0 && order.size() <= g.edges.size());
        if (e != 0) throw cpm::Error("hlc_platoon: the lane graph is not one loop");
    }
    /// The pose at position `at` along the loop.
    cpm::routing::Pose pose_at(const LaneGraph& g, double at) const
    {
        at = std::fmod(std::fmod(at, length) + length, length);
        for (size_t e : order) {
            if (at <= start.at(e) + g.edges[e].length()) return g.pose_at(e, at - start.at(e));
        }
        return g.pose_at(order.back(), g.edges[order.back()].length());
    }
};

int run(int argc, char** argv)
{
    auto parsed = cpm::cli::parse_flags(argc, argv, {{"--lanes", true}, {"--vehicle_ids", true}, {"--speed", true}, {"--gap", true}}, "hlc_platoon");
    if (!parsed.has("--lanes")) throw cpm::cli::UsageError("hlc_platoon: --lanes is required (a lane graph that is one loop)");
    if (!parsed.has("--vehicle_ids")) throw cpm::cli::UsageError("hlc_platoon: --vehicle_ids is required (e.g. 1,2,3,4)");
    std::vector<uint8_t> ids;
    for (const auto& id : cpm::cli::split_list("--vehicle_ids", parsed.get("--vehicle_ids"))) {
        ids.push_back(uint8_t(cpm::cli::parse_integer("--vehicle_ids", id, 1, 255)));
    }
    const double speed = cpm::cli::parse_number("--speed", parsed.get("--speed", "0.6"), 0.05, 2.0);
    const double gap_s = double(cpm::cli::parse_duration("--gap", parsed.get("--gap", "1.0s"))) * 1e-9;
    const LaneGraph graph = cpm::routing::load_lane_graph_or_throw(parsed.get("--lanes"));
    const Loop loop(graph);
    cpm::init(argc, argv);

    cpm::hlc::Communicator hlc(ids);
    cpm::Writer<VehicleCommandTrajectory> trajectories(cpm::topics::vehicle_command_trajectory.name, cpm::topics::vehicle_command_trajectory.writer);
    constexpr double kMinGap = 0.45, kAccel = 0.8, kStep = 0.1, kHorizon = 1.5;
    hlc.on_first_timestep([&](const VehicleStateList& list) {
        CPM_LOG_INFO("hlc_platoon: first step at %llu with %zu of %zu cars", (unsigned long long)list.t_now(), list.state_list().size(), ids.size());
    });
    hlc.on_each_timestep([&](const VehicleStateList& list) {
        // Each car's place along the loop.
        std::map<uint8_t, std::pair<double, double>> at;  // id -> (position, speed)
        for (const auto& s : list.state_list()) {
            const auto p = graph.project({s.pose().x(), s.pose().y(), s.pose().yaw()}, 0.5, 1.2);
            if (p) at[s.vehicle_id()] = {loop.start.at(p->edge) + p->s, s.speed()};
        }
        for (const auto& [id, mine] : at) {
            double ahead = loop.length;
            for (const auto& [other, theirs] : at) {
                if (other != id) ahead = std::min(ahead, std::fmod(theirs.first - mine.first + loop.length, loop.length));
            }
            const double allowed = std::max(0.0, (ahead - kMinGap) / gap_s);
            const double target = std::min(speed, allowed);
            VehicleCommandTrajectory command;
            command.vehicle_id(id);
            cpm::stamp_message(command, list.t_now(), 0);
            double s = mine.first, v = mine.second;
            for (double t = 0; t <= kHorizon + 1e-9; t += kStep) {
                const auto pose = loop.pose_at(graph, s);
                TrajectoryPoint point;
                point.t().nanoseconds(list.t_now() + uint64_t(std::llround(t * 1e9)));
                point.px(pose.x);
                point.py(pose.y);
                point.vx(v * std::cos(pose.yaw));
                point.vy(v * std::sin(pose.yaw));
                command.trajectory_points().push_back(point);
                v = v < target ? std::min(target, v + kAccel * kStep) : std::max(target, v - 2 * kAccel * kStep);
                s += v * kStep;
            }
            if (!trajectories.write(command)) CPM_LOG_WARN("hlc_platoon: DDS refused vehicle %u's trajectory", unsigned(id));
        }
    });
    hlc.start();
    std::printf("{\"steps\":%llu,\"cancelled\":%llu,\"failed\":%llu}\n", (unsigned long long)hlc.steps(),
                (unsigned long long)hlc.cancelled_steps(), (unsigned long long)hlc.failed_steps());
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "hlc_platoon", kHelp, run); }
