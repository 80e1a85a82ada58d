// bench_hlc: what cpm's high-level-controller contract costs per period, 20 cars. In one process,
// as a lab would run them on one computer: the lab's cars' states (20 writers at 50 Hz), an
// hlc_middleware (cpm::hlc::Middleware) on the lab's domain and the controller's, and a
// controller (cpm::hlc::Communicator) that answers each list with a 16-point trajectory for
// every car. Measured: the list built (both MultiVehicleReaders read, the list filled), and a
// step end to end — the list written → the controller called → its 20 commands written → its
// answer back at the middleware (the middleware's own response time). No peer: cpm_lab's
// middleware is not in Debian; the figures say what a period's budget loses to the contract.
#include <bench_common.hpp>

#include <cpm/MultiVehicleReader.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/hlc/Communicator.hpp>
#include <cpm/hlc/Middleware.hpp>
#include <cpm/init.hpp>
#include <cpm/percentile.hpp>
#include <cpm/stamp_message.hpp>
#include <cpm/topics.hpp>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <thread>

namespace {

namespace t = cpm::topics;
constexpr int kCars = 20;

VehicleCommandTrajectory trajectory(uint8_t id, uint64_t t_now)
{
    VehicleCommandTrajectory c;
    c.vehicle_id(id);
    cpm::stamp_message(c, t_now, 0);
    for (int k = 0; k < 16; ++k) {
        TrajectoryPoint p;
        p.t().nanoseconds(t_now + uint64_t(k) * 100'000'000ull);
        p.px(0.1 * k);
        p.py(id);
        p.vx(0.5);
        c.trajectory_points().push_back(p);
    }
    return c;
}

}  // namespace

int main(int argc, char** argv)
{
    cpm::init(argc, argv);
    const int seconds = argc > 1 && argv[1][0] != '-' ? std::atoi(argv[1]) : 20;
    const int lab = cpm::init_settings().domain_id;
    std::vector<uint8_t> ids;
    for (int i = 1; i <= kCars; ++i) ids.push_back(uint8_t(i));
    bench::print_machine("20 cars, a 50 ms period, one process (the lab's cars, the middleware, the controller); " + std::to_string(seconds) + " s");

    // The cars' states at 50 Hz.
    std::atomic<bool> stop{false};
    std::thread cars([&] {
        cpm::Writer<VehicleState> states(t::vehicle_state.name, t::vehicle_state.writer);
        while (!stop) {
            const uint64_t now = cpm::get_time_ns();
            for (uint8_t id : ids) {
                VehicleState s;
                s.vehicle_id(id);
                s.speed(0.5);
                cpm::stamp_message(s, now, 0);
                (void)states.write(s);
            }
            std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
    });

    // The list built, by itself.
    std::vector<double> build_us;
    {
        cpm::MultiVehicleReader<VehicleState> states(t::vehicle_state.name, ids);
        cpm::MultiVehicleReader<VehicleObservation> observations(t::vehicle_observation.name, ids);
        cpm::hlc::MiddlewareCore core({.name = "bench", .vehicle_ids = ids, .period_ns = 50'000'000, .controller_domain = (lab + 1) % 233});
        std::this_thread::sleep_for(std::chrono::seconds(1));
        for (int i = 0; i < 2000; ++i) {
            const auto t0 = std::chrono::steady_clock::now();
            const uint64_t now = cpm::get_time_ns();
            const auto list = core.begin_period(now, states.get_samples(now), observations.get_samples(now), 0);
            build_us.push_back(std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count());
            if (list.state_list().size() != kCars) {
                std::fprintf(stderr, "bench_hlc: the list held %zu of %d cars\n", list.state_list().size(), kCars);
                return 1;
            }
        }
    }

    cpm::hlc::MiddlewareOptions o{.name = "bench", .vehicle_ids = ids, .period_ns = 50'000'000, .controller_domain = (lab + 1) % 233};
    o.wait_for_start = false;
    cpm::hlc::Middleware middleware(o);
    cpm::ParticipantOptions po;
    po.domain_id = o.controller_domain;
    po.name = "bench_controller";
    cpm::Participant controller_side(po);
    std::atomic<bool> stop_controller{false};
    cpm::hlc::Communicator hlc(ids, {.participant = &controller_side, .stop_requested = [&] { return stop_controller.load(); }});
    cpm::Writer<VehicleCommandTrajectory> out(controller_side, t::vehicle_command_trajectory.name, t::vehicle_command_trajectory.writer);
    std::vector<double> step_us;
    hlc.on_each_timestep([&](const VehicleStateList& list) {
        const auto t0 = std::chrono::steady_clock::now();
        for (const auto& s : list.state_list()) (void)out.write(trajectory(s.vehicle_id(), list.t_now()));
        step_us.push_back(std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count());
    });
    std::thread controller([&] { hlc.start(); });
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(seconds);
    middleware.run([&] { return std::chrono::steady_clock::now() >= until; });
    stop_controller = true;
    controller.join();
    stop = true;
    cars.join();

    const auto& core = middleware.core();
    auto response = core.response_ms();
    bench::Stats list_built = bench::stats_of(build_us), written = bench::stats_of(step_us), end_to_end = bench::stats_of([&] {
        std::vector<double> us;
        for (double ms : response) us.push_back(ms * 1000);
        return us;
    }());
    bench::print_header("µs per period, 20 cars");
    bench::print_row("list built (2 readers, list filled)", list_built);
    bench::print_row("controller: 20 commands written", written);
    bench::print_row("step: list out → answer back", end_to_end);
    std::printf("periods %llu, answered %llu, unanswered %llu, commands forwarded %llu, refused %llu\n", (unsigned long long)core.periods(),
                (unsigned long long)core.answered_periods(), (unsigned long long)core.unanswered_periods(), (unsigned long long)core.forwarded(),
                (unsigned long long)core.refused());
    for (const auto& [what, s] : {std::pair{"list built", list_built}, std::pair{"step end to end", end_to_end}}) {
        bench::record({.bench = "hlc", .what = std::string(what) + " p50 (20 cars)", .unit = "µs", .cpm = s.p50});
        bench::record({.bench = "hlc", .what = std::string(what) + " p99 (20 cars)", .unit = "µs", .cpm = s.p99});
    }
    const bool whole = core.refused() == 0 && core.forwarded() >= core.answered_periods() * kCars;
    return whole ? 0 : 1;
}
