#include <cpm/topics.hpp>
#include <cpm/vehicle/FirmwareSimNode.hpp>

#include <cpm/Error.hpp>
#include <cpm/Logging.hpp>
#include <cpm/Participant.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/Timer.hpp>
#include <cpm/init.hpp>
#include <cpm/timer_ids.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/stamp_message.hpp>
#include <cpm/vehicle/SerialPort.hpp>

#include "OtherCarsReader.hpp"
#include "SimulatedWait.hpp"
#include "WriterThread.hpp"

#include <VehicleObservation.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <thread>
#include <cstdio>
#include <set>
#include <random>

namespace cpm::vehicle {

namespace {

/// One car of the process: its controller and its line.
struct Car
{
    Car(const SimulatedCar& c, const FirmwareSimNodeOptions& o)
        : options(c), sim(o.parameters, o.world, c.start, c.vehicle_id, c.seed), corruption(c.seed)
    {
        if (!o.device.empty()) {
            port = std::make_unique<SerialPort>(o.device, o.baud);
            device = o.device;
        } else {
            pty = std::make_unique<PseudoTerminal>(c.link);
            device = pty->device_path();
        }
    }
    long read_line(uint8_t* data, size_t size) { return pty ? pty->read_available(data, size) : port->read_some(data, size, 0); }
    void write_line(const std::vector<uint8_t>& frame)
    {
        if (pty) {
            pty->write_frame(frame.data(), frame.size());
        } else {
            port->write_all(frame.data(), frame.size());
        }
    }

    SimulatedCar options;
    FirmwareSim sim;
    std::mt19937 corruption;
    std::unique_ptr<PseudoTerminal> pty;
    std::unique_ptr<SerialPort> port;
    std::string device;
    std::pair<MotorMode, uint16_t> traced{MotorMode::brake, 0};
    bool host_silent = false;  ///< simulated time: the last state packet went unanswered
};

void checked(const FirmwareSimNodeOptions& o)
{
    if (o.cars.empty()) throw Error("firmware_sim: no car to simulate");
    std::set<uint8_t> ids;
    for (const auto& c : o.cars) {
        if (c.vehicle_id == 0) throw Error("firmware_sim: vehicle id 0 is not a car's (ids are 1..255)");
        if (!ids.insert(c.vehicle_id).second)
            throw Error("firmware_sim: vehicle " + std::to_string(c.vehicle_id) + " is given twice");
    }
    if (o.cars.size() > 1 && !o.device.empty())
        throw Error("firmware_sim: a serial device carries one car; " + std::to_string(o.cars.size()) + " were given");
    if (o.cars.size() > 1 && o.trace_pwm)
        throw Error("firmware_sim: the pwm trace is for one car; " + std::to_string(o.cars.size()) + " were given");
}

std::set<uint8_t> ids_of(const FirmwareSimNodeOptions& o)
{
    std::set<uint8_t> ids;
    for (const auto& c : o.cars) ids.insert(c.vehicle_id);
    return ids;
}

}  // namespace

struct FirmwareSimNode::Impl
{
    explicit Impl(FirmwareSimNodeOptions o)
        : options(std::move(o)), participant(Participant::default_participant()),
          observations(participant, options.truth_topic, topics::vehicle_observation.writer),
          others(participant, options.truth_topic, ids_of(options))
    {
        checked(options);
        for (const auto& c : options.cars) cars.push_back(std::make_unique<Car>(c, options));
        Logging::instance().connect();  // the cars' first message (a late tick) must not create DDS entities
    }

    void trace(Car& car, uint64_t now);
    void read_lines();
    void await_answers();
    void tick(uint64_t t_nominal);
    void publish(Car& car, uint64_t t_model);
    void see_each_other();
    void report_collisions(Car& car);

    FirmwareSimNodeOptions options;
    std::vector<std::unique_ptr<Car>> cars;
    Participant& participant;
    Writer<VehicleObservation> observations;
    OtherCarsReader others;  ///< cars of other processes
    std::shared_ptr<Timer> timer;
    bool simulated = false;  ///< on the lab's simulated clock (--simulated_time)
    uint64_t physics_period_ns = 0, steps_per_state = 1, max_catch_up = 1;
    uint64_t last_tick_ns = 0, steps = 0, skipped_steps = 0;
    bool ticked = false;  ///< a first tick ran (on the simulated clock it is at lab time 0)
    WriterThread<VehicleObservation> publisher{observations, options.truth_topic, 256, !init_settings().simulated_time};
};

void FirmwareSimNode::Impl::trace(Car& car, uint64_t now)
{
    if (!options.trace_pwm) return;
    auto held = car.sim.motor_command();
    if (held == car.traced) return;
    car.traced = held;
    std::printf("pwm %llu %d %u\n", static_cast<unsigned long long>(now), static_cast<int>(held.first), unsigned(held.second));
    std::fflush(stdout);
}

void FirmwareSimNode::Impl::report_collisions(Car& car)
{
    for (const auto& c : car.sim.take_collisions()) CPM_LOG_WARN("%s", describe_collision(car.options.vehicle_id, c).c_str());
}

void FirmwareSimNode::Impl::publish(Car& car, uint64_t t_model)
{
    if (car.sim.drop_observation()) return;
    // Stamped with the model time the pose belongs to, not the moment a late tick ran: a
    // loaded machine delays the tick, not the car, and a speed computed from the stamps
    // must not see that delay.
    VehicleObservation o;
    stamp_message(o, t_model, 0);
    o.vehicle_id(car.options.vehicle_id);
    auto pose = car.sim.observed_pose();
    o.pose().x(pose.x);
    o.pose().y(pose.y);
    o.pose().yaw(pose.yaw);
    publisher.write(o);  // in real time from its own thread: the cars run on while a write stalls
}

void FirmwareSimNode::Impl::see_each_other()
{
    const uint64_t now = get_time_ns();
    std::vector<Pose> everyone = others.current(now);  // other processes' cars first, then this process's in order
    const size_t foreign = everyone.size();
    for (const auto& car : cars) everyone.push_back(car->sim.model().pose());
    std::vector<Pose> poses;
    for (size_t k = 0; k < cars.size(); ++k) {
        poses.assign(everyone.begin(), everyone.begin() + long(foreign));
        for (size_t j = 0; j < cars.size(); ++j) {
            if (j != k) poses.push_back(everyone[foreign + j]);
        }
        cars[k]->sim.set_other_cars(poses);
    }
}

void FirmwareSimNode::Impl::read_lines()
{
    uint8_t buffer[512];
    for (auto& car : cars) {
        for (long n; (n = car->read_line(buffer, sizeof buffer)) > 0;) {
            car->sim.receive(buffer, size_t(n));
            trace(*car, get_time_ns());
        }
    }
}

void FirmwareSimNode::Impl::await_answers()
{
    // In simulated time the hosts answered the last state packets before the lab clock moved
    // on (their timers tick in our step), but a pty hands bytes over asynchronously: wait for
    // answers still in flight (kSimulatedPacketWait of real time at most: 100 ms ran out on a
    // loaded machine, and that run differed from the one before). A car whose host is gone is
    // not waited for again until it answers once more.
    (void)await_bytes([&] {
        read_lines();
        for (const auto& car : cars) {
            if (!car->sim.answered() && !car->host_silent) return false;
        }
        return true;
    });
    for (auto& car : cars) {
        const bool silent = !car->sim.answered();
        if (silent && !car->host_silent) say_host_silent(car->options.vehicle_id);
        car->host_silent = silent;
    }
}

void FirmwareSimNode::Impl::tick(uint64_t t_nominal)
{
    if (simulated) {
        await_answers();
    } else {
        read_lines();
    }
    // Catch up on ticks the timer skipped (up to 1 s), so model time keeps pace with real
    // time; but send only one state packet however many fell due: a controller that fell
    // behind must not flood its host (it would only use the newest anyway).
    // The first tick steps once. Not told by last_tick_ns == 0: on the simulated clock the first
    // tick is at 0, and the second then stepped once instead of a state period's worth, sent no
    // state packet, and the bridge waited 100 ms for it.
    uint64_t due = ticked ? (t_nominal - last_tick_ns) / physics_period_ns : 1;
    ticked = true;
    if (due > max_catch_up) {
        skipped_steps += due - max_catch_up;
        due = max_catch_up;
    }
    last_tick_ns = t_nominal;
    bool state_due = false;
    for (uint64_t i = 0; i < due; ++i) {
        for (auto& car : cars) car->sim.step();
        if (++steps % steps_per_state == 0) state_due = true;
    }
    for (auto& car : cars) report_collisions(*car);
    if (state_due) {
        for (auto& car : cars) {
            auto frame = encode_frame(car->sim.make_state_packet());
            if (options.corrupt_rate > 0 &&
                std::uniform_real_distribution<double>(0, 1)(car->corruption) < options.corrupt_rate) {
                frame[car->corruption() % frame.size()] ^= uint8_t(1 + car->corruption() % 255);
            }
            car->write_line(frame);
            publish(*car, t_nominal);
        }
        see_each_other();
    }
    for (auto& car : cars) trace(*car, get_time_ns());
}

std::string FirmwareSimNode::timer_name(uint8_t first_vehicle_id) { return timer_ids::firmware_sim(first_vehicle_id); }

FirmwareSimNode::FirmwareSimNode(FirmwareSimNodeOptions options) : impl_(std::make_unique<Impl>(std::move(options)))
{
    if (impl_->cars.size() == 1) {
        std::printf("device: %s\n", impl_->cars[0]->device.c_str());
    } else {
        for (const auto& car : impl_->cars) std::printf("device %u: %s\n", unsigned(car->options.vehicle_id), car->device.c_str());
    }
    std::fflush(stdout);
}

FirmwareSimNode::~FirmwareSimNode() = default;

std::vector<std::pair<uint8_t, std::string>> FirmwareSimNode::devices() const
{
    std::vector<std::pair<uint8_t, std::string>> out;
    for (const auto& car : impl_->cars) out.emplace_back(car->options.vehicle_id, car->device);
    return out;
}

void FirmwareSimNode::run(const std::function<bool()>& stop_requested)
{
    auto& d = *impl_;
    const auto& p = d.options.parameters;
    d.physics_period_ns = static_cast<uint64_t>(1e9 / p.physics_rate);
    d.steps_per_state = std::max<uint64_t>(1, std::llround(p.physics_rate / p.state_rate));
    d.max_catch_up = std::max<uint64_t>(1, uint64_t(p.physics_rate));  // 1 s of model time
    // Real time: a tick per physics step, so commands act within one. Simulated time: a tick
    // per state packet (the lab's clock steps through every tick of every node, and the host
    // answers between two), the physics steps in between run at once; and a state packet on
    // the first tick, so the host's first tick has one to answer.
    d.simulated = init_settings().simulated_time;
    // Real time: the microcontrollers' timer never reads a line itself (a pty's read waits for
    // the kernel's worker). Simulated time: the tick reads what the hosts answered, at once.
    if (!d.simulated) {
        for (auto& car : d.cars) {
            if (car->pty) car->pty->read_on_own_thread(init_settings().realtime);
        }
    }
    const uint64_t period = d.simulated ? d.physics_period_ns * d.steps_per_state : d.physics_period_ns;
    if (d.simulated) d.steps = d.steps_per_state - 1;
    d.timer = Timer::create(d.participant, timer_name(d.cars[0]->options.vehicle_id), period,
                            d.simulated ? timer_ids::kSimulatedCarOffset_ns : 0,
                            cpm::TimerOptions{.wait_for_start = false, .simulated_time_allowed = true});
    d.timer->run_until(stop_requested, [&](uint64_t t_nominal) { d.tick(t_nominal); });
}

std::string FirmwareSimNode::stats_json() const
{
    const auto& d = *impl_;
    std::string lines;
    for (const auto& car : d.cars) {
        const auto s = car->sim.stats();
        nlohmann::ordered_json j{{"vehicle_id", car->options.vehicle_id},
                                 {"state_packets", s.state_packets},
                                 {"unanswered_states", s.unanswered_states},
                                 {"commands", s.commands},
                                 {"wrong_vehicle", s.wrong_vehicle},
                                 {"watchdog_stops", s.watchdog_stops},
                                 {"wall_collisions", s.wall_collisions},
                                 {"missed_ticks", d.timer ? d.timer->missed_deadlines() : 0},
                                 {"model_steps_dropped", d.skipped_steps},
                                 {"decoder_errors",
                                  {{"oversize", s.decoder.oversize},
                                   {"bad_cobs", s.decoder.bad_cobs},
                                   {"too_short", s.decoder.too_short},
                                   {"bad_crc", s.decoder.bad_crc},
                                   {"bad_packet", s.decoder.bad_packet}}}};
        lines += (lines.empty() ? "" : "\n") + j.dump();
    }
    return lines;
}

}  // namespace cpm::vehicle
