// A controller for the tests of users' controllers: drives each of its cars straight ahead at
// 0.3 m/s; --sleep makes every step take that long (a controller too slow for its period);
// --also_command N sends car N a command too (a car it was not given); --crash_after N aborts in
// its N-th step.
#include <cpm/CommandLine.hpp>
#include <cpm/Writer.hpp>
#include <cpm/hlc/Communicator.hpp>
#include <cpm/init.hpp>
#include <cpm/stamp_message.hpp>
#include <cpm/topics.hpp>

#include <VehicleCommandTrajectory.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cmath>
#include <thread>

namespace {

VehicleCommandTrajectory straight_ahead(uint8_t id, uint64_t t_now, double x, double y, double yaw, double v)
{
    VehicleCommandTrajectory c;
    c.vehicle_id(id);
    cpm::stamp_message(c, t_now, 0);
    for (int k = 0; k <= 10; ++k) {
        const double t = 0.1 * k;
        TrajectoryPoint p;
        p.t().nanoseconds(t_now + uint64_t(k) * 100'000'000ull);
        p.px(x + v * t * std::cos(yaw));
        p.py(y + v * t * std::sin(yaw));
        p.vx(v * std::cos(yaw));
        p.vy(v * std::sin(yaw));
        c.trajectory_points().push_back(p);
    }
    return c;
}

int run(int argc, char** argv)
{
    auto parsed = cpm::cli::parse_flags(argc, argv, {{"--vehicle_ids", true}, {"--sleep", true}, {"--also_command", true}, {"--crash_after", true}}, "test_controller");
    std::vector<uint8_t> ids;
    for (const auto& id : cpm::cli::split_list("--vehicle_ids", parsed.get("--vehicle_ids"))) {
        ids.push_back(uint8_t(cpm::cli::parse_integer("--vehicle_ids", id, 1, 255)));
    }
    const auto sleep = std::chrono::nanoseconds(cpm::cli::parse_duration("--sleep", parsed.get("--sleep", "0s")));
    const int also = int(cpm::cli::parse_integer("--also_command", parsed.get("--also_command", "0"), 0, 255));
    const long long crash_after = cpm::cli::parse_integer("--crash_after", parsed.get("--crash_after", "0"), 0, 1'000'000);
    long long steps = 0;
    cpm::init(argc, argv);
    cpm::hlc::Communicator hlc(ids);
    cpm::Writer<VehicleCommandTrajectory> out(cpm::topics::vehicle_command_trajectory.name, cpm::topics::vehicle_command_trajectory.writer);
    hlc.on_each_timestep([&](const VehicleStateList& list) {
        std::this_thread::sleep_for(sleep);
        if (crash_after && ++steps == crash_after) {
            std::fprintf(stderr, "test_controller: crashing on purpose in step %lld\n", steps);
            std::abort();
        }
        for (const auto& s : list.state_list()) {
            (void)out.write(straight_ahead(s.vehicle_id(), list.t_now(), s.pose().x(), s.pose().y(), s.pose().yaw(), 0.3));
        }
        if (also) (void)out.write(straight_ahead(uint8_t(also), list.t_now(), 0, 0, 0, 0.3));
    });
    hlc.start();
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "test_controller", "test_controller --vehicle_ids 1,2 [--sleep 300ms] [--also_command N]\n", run); }
