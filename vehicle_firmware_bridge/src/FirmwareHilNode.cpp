#include <cpm/vehicle/FirmwareHil.hpp>

#include <cpm/Error.hpp>
#include <cpm/LogThrottle.hpp>
#include <cpm/Logging.hpp>
#include <cpm/Participant.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/Timer.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/init.hpp>
#include <cpm/stamp_message.hpp>
#include <cpm/timer_ids.hpp>
#include <cpm/topics.hpp>

#include "OtherCarsReader.hpp"
#include "SimulatedWait.hpp"
#include "WriterThread.hpp"

#include <VehicleObservation.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <thread>

namespace cpm::vehicle {

struct FirmwareHilNode::Impl
{
    explicit Impl(FirmwareHilOptions o)
        : vehicle_id(o.car.vehicle_id), truth_topic(o.truth_topic), hil(std::move(o)), participant(Participant::default_participant()),
          observations(participant, truth_topic, topics::vehicle_observation.writer),
          others(participant, truth_topic, {vehicle_id})
    {
        hil.on_state_period([this](uint64_t chip_ns) { publish(chip_ns); });
        Logging::instance().connect();  // the chip's first message (a late tick) must not create DDS entities
    }

    void publish(uint64_t chip_ns)
    {
        auto& car = hil.car();
        see_others(t0 + chip_ns);
        if (car.drop_observation()) return;
        VehicleObservation o;
        stamp_message(o, t0 + chip_ns, 0);
        o.vehicle_id(vehicle_id);
        const auto pose = car.observed_pose();
        o.pose().x(pose.x);
        o.pose().y(pose.y);
        o.pose().yaw(pose.yaw);
        publisher.write(o);  // in real time the chip runs on while a write stalls
    }

    /// The other cars' bodies, for the rangers: those seen within the last second.
    void see_others(uint64_t now)
    {
        hil.car().set_other_cars(others.current(now));
    }

    /// Simulated time: the bridge answered the last state packet before the lab clock moved on,
    /// but the pty hands its bytes over on its own thread; wait for them (kSimulatedPacketWait of
    /// real time at most). A bridge that is gone is not waited for again until it answers once more.
    void await_answer()
    {
        const bool answered = await_bytes([&] { return host_silent || hil.frame_waiting(); }) && hil.frame_waiting();
        if (!answered && !host_silent) say_host_silent(vehicle_id);
        host_silent = !answered;
    }

    /// The chip's last state packet out of uart_pty's hands before the tick ends.
    void await_output()
    {
        (void)await_bytes([&] { return !hil.output_pending(); });
    }

    uint8_t vehicle_id;
    std::string truth_topic;
    FirmwareHil hil;
    Participant& participant;
    Writer<VehicleObservation> observations;
    OtherCarsReader others;
    std::shared_ptr<Timer> timer;
    uint64_t t0 = 0;  ///< lab time of the chip's reset
    LogThrottle lag_log;
    bool host_silent = false;
    WriterThread<VehicleObservation> publisher{observations, truth_topic, 256, !init_settings().simulated_time};
};

FirmwareHilNode::FirmwareHilNode(FirmwareHilOptions options) : impl_(std::make_unique<Impl>(std::move(options)))
{
    std::printf("device: %s\n", impl_->hil.device().c_str());
    std::fflush(stdout);
}

FirmwareHilNode::~FirmwareHilNode() = default;

const std::string& FirmwareHilNode::device() const { return impl_->hil.device(); }

void FirmwareHilNode::run(const std::function<bool()>& stop_requested)
{
    auto& d = *impl_;
    const auto& p = d.hil.car().parameters();
    const bool simulated = init_settings().simulated_time;
    // Simulated time: a tick per state packet. The chip's clock runs 10 ms ahead of the lab's
    // so the packet it starts at each multiple of 20 ms is on the line (4 ms at 115200 baud)
    // before the tick ends. Real time: the chip catches up with the wall clock every 1 ms.
    const uint64_t state_period = uint64_t(1e9 / p.state_rate);
    const uint64_t period = simulated ? state_period : 2'000'000ull;
    const uint64_t lead = simulated ? state_period / 2 : 0;
    d.timer = Timer::create(d.participant, timer_ids::firmware_sim(d.vehicle_id), period, 0,
                            cpm::TimerOptions{.wait_for_start = false, .simulated_time_allowed = true});
    d.timer->run_until(stop_requested, [&](uint64_t t_nominal) {
        if (d.t0 == 0) d.t0 = t_nominal - lead;
        if (simulated) d.await_answer();
        d.hil.run_to(t_nominal - d.t0);
        if (simulated) {
            d.await_output();
        } else {
            const uint64_t now = get_time_ns();
            const double lag_ms = double(int64_t(now - d.t0) - int64_t(d.hil.chip_ns())) * 1e-6;
            d.hil.note_lag(lag_ms);
            // A chip a state period behind the wall clock sends its packets late: say so, once a second.
            uint64_t held_back = 0;
            if (lag_ms > 20.0 && d.lag_log.allow(now, held_back)) {
                CPM_LOG_WARN("vehicle %u: the simulated chip is %.1f ms behind the wall clock (this machine is too busy to run it in "
                             "real time; %llu more such ticks since the last report)",
                             unsigned(d.vehicle_id), lag_ms, static_cast<unsigned long long>(held_back));
            }
        }
    });
}

std::string FirmwareHilNode::stats_json() const
{
    const auto& d = *impl_;
    const auto s = d.hil.stats();
    const double chip_s = double(s.cycles) / 16e6;
    nlohmann::ordered_json j{{"vehicle_id", d.vehicle_id},
                             {"chip_seconds", chip_s},
                             {"chip_cycles", s.cycles},
                             {"wall_seconds_running", s.wall_s},
                             {"simulated_mhz", s.wall_s > 0 ? double(s.cycles) / s.wall_s * 1e-6 : 0.0},
                             {"real_time_factor", s.wall_s > 0 ? chip_s / s.wall_s : 0.0},
                             {"lag_max_ms", s.lag_max_ms},
                             {"state_packets", s.state_packets},
                             {"watchdog_stops", s.watchdog_stops},
                             {"bad_frames_reported", s.bad_frames_seen},
                             {"motor_changes", s.motor_changes},
                             {"wall_collisions", s.wall_collisions},
                             {"corrupted_frames", s.corrupted_frames},
                             {"missed_ticks", d.timer ? d.timer->missed_deadlines() : 0}};
    return j.dump();
}

}  // namespace cpm::vehicle
