#include <cpm/topics.hpp>
#include <cpm/vehicle/FirmwareSimNode.hpp>

#include <cpm/Logging.hpp>
#include <cpm/Participant.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/Timer.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/stamp_message.hpp>
#include <cpm/vehicle/SerialPort.hpp>

#include <VehicleObservation.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <condition_variable>
#include <mutex>
#include <optional>
#include <thread>
#include <cstdio>
#include <map>
#include <random>

namespace cpm::vehicle {

struct FirmwareSimNode::Impl
{
    explicit Impl(FirmwareSimNodeOptions o)
        : options(std::move(o)), sim(options.parameters, options.world, options.start, options.vehicle_id, options.seed),
          corruption(options.seed), participant(Participant::default_participant()),
          observations(participant, topics::vehicle_observation.name, topics::vehicle_observation.writer),
          others(participant, topics::vehicle_observation.name, topics::vehicle_observation.reader)
    {
        if (!options.device.empty()) {
            port = std::make_unique<SerialPort>(options.device, options.baud);
            device = options.device;
        } else {
            pty = std::make_unique<PseudoTerminal>(options.link);
            device = pty->device_path();
        }
        publisher = std::thread([this] { publish_loop(); });
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
    void trace(uint64_t now);
    void tick(uint64_t t_nominal);
    void publish_and_see_others(uint64_t t_model);
    void report_collisions();
    void publish_loop();

    FirmwareSimNodeOptions options;
    FirmwareSim sim;
    std::mt19937 corruption;
    std::unique_ptr<PseudoTerminal> pty;
    std::unique_ptr<SerialPort> port;
    std::string device;
    Participant& participant;
    Writer<VehicleObservation> observations;
    ReaderAbstract<VehicleObservation> others;
    std::map<uint8_t, std::pair<uint64_t, Pose>> other_cars;
    std::shared_ptr<Timer> timer;
    uint64_t physics_period_ns = 0, steps_per_state = 1, max_catch_up = 1;
    uint64_t last_tick_ns = 0, steps = 0, skipped_steps = 0;
    std::pair<MotorMode, uint16_t> traced{MotorMode::Brake, 0};
    // The true pose goes out from a thread of its own: a DDS write can stall (a reader's process
    // killed while holding its shared-memory port), and the microcontroller's clock, commands
    // and watchdog must not wait for it. Only the newest observation is kept.
    std::mutex publish_mutex;
    std::condition_variable publish_ready;
    std::optional<VehicleObservation> to_publish;
    bool publishing = true;
    std::thread publisher;  // started once the line is open (the constructor may throw before)
};

void FirmwareSimNode::Impl::publish_loop()
{
    for (;;) {
        VehicleObservation o;
        {
            std::unique_lock<std::mutex> lock(publish_mutex);
            publish_ready.wait(lock, [&] { return to_publish || !publishing; });
            if (!to_publish) return;
            o = *to_publish;
            to_publish.reset();
        }
        (void)observations.write(o);
    }
}

void FirmwareSimNode::Impl::trace(uint64_t now)
{
    if (!options.trace_pwm) return;
    auto held = sim.motor_command();
    if (held == traced) return;
    traced = held;
    std::printf("pwm %llu %d %u\n", static_cast<unsigned long long>(now), static_cast<int>(held.first), unsigned(held.second));
    std::fflush(stdout);
}

void FirmwareSimNode::Impl::report_collisions()
{
    for (const auto& c : sim.take_collisions()) {
        CPM_LOG_WARN("vehicle %u: hit the wall [%.3f, %.3f, %.3f, %.3f] at x %.3f y %.3f yaw %.3f; stopped against it",
                     unsigned(options.vehicle_id), c.wall.x1, c.wall.y1, c.wall.x2, c.wall.y2, c.pose.x, c.pose.y,
                     c.pose.yaw);
    }
}

void FirmwareSimNode::Impl::publish_and_see_others(uint64_t t_model)
{
    uint64_t now = get_time_ns();
    if (!sim.drop_observation()) {
        // Stamped with the model time the pose belongs to, not the moment a late tick ran: a
        // loaded machine delays the tick, not the car, and a speed computed from the stamps
        // must not see that delay.
        VehicleObservation o;
        stamp_message(o, t_model, 0);
        o.vehicle_id(options.vehicle_id);
        auto pose = sim.observed_pose();
        o.pose().x(pose.x);
        o.pose().y(pose.y);
        o.pose().yaw(pose.yaw);
        std::lock_guard<std::mutex> lock(publish_mutex);
        to_publish = o;
        publish_ready.notify_one();
    }
    for (auto& o : others.take()) {
        if (o.vehicle_id() == options.vehicle_id) continue;
        other_cars[o.vehicle_id()] = {o.header().create_stamp().nanoseconds(), {o.pose().x(), o.pose().y(), o.pose().yaw()}};
    }
    std::vector<Pose> poses;
    for (auto it = other_cars.begin(); it != other_cars.end();) {
        // A car not seen for a second has left the world.
        if (it->second.first + 1'000'000'000ull < now) {
            it = other_cars.erase(it);
        } else {
            poses.push_back(it->second.second);
            ++it;
        }
    }
    sim.set_other_cars(poses);
}

void FirmwareSimNode::Impl::tick(uint64_t t_nominal)
{
    uint8_t buffer[512];
    for (long n; (n = read_line(buffer, sizeof buffer)) > 0;) {
        sim.receive(buffer, size_t(n));
        trace(get_time_ns());
    }
    // Catch up on ticks the timer skipped (up to 1 s), so model time keeps pace with real
    // time; but send only one state packet however many fell due: a controller that fell
    // behind must not flood its host (it would only use the newest anyway).
    uint64_t due = last_tick_ns == 0 ? 1 : (t_nominal - last_tick_ns) / physics_period_ns;
    if (due > max_catch_up) {
        skipped_steps += due - max_catch_up;
        due = max_catch_up;
    }
    last_tick_ns = t_nominal;
    bool state_due = false;
    for (uint64_t i = 0; i < due; ++i) {
        sim.step();
        if (++steps % steps_per_state == 0) state_due = true;
    }
    report_collisions();
    if (state_due) {
        auto frame = encode_frame(sim.make_state_packet());
        if (options.corrupt_rate > 0 && std::uniform_real_distribution<double>(0, 1)(corruption) < options.corrupt_rate) {
            frame[corruption() % frame.size()] ^= uint8_t(1 + corruption() % 255);
        }
        write_line(frame);
        publish_and_see_others(t_nominal);
    }
    trace(get_time_ns());
}

FirmwareSimNode::FirmwareSimNode(FirmwareSimNodeOptions options) : impl_(std::make_unique<Impl>(std::move(options)))
{
    std::printf("device: %s\n", impl_->device.c_str());
    std::fflush(stdout);
}

FirmwareSimNode::~FirmwareSimNode()
{
    {
        std::lock_guard<std::mutex> lock(impl_->publish_mutex);
        impl_->publishing = false;
        impl_->publish_ready.notify_one();
    }
    impl_->publisher.join();
}

const std::string& FirmwareSimNode::device_path() const { return impl_->device; }

void FirmwareSimNode::run(const std::function<bool()>& stop_requested)
{
    auto& d = *impl_;
    const auto& p = d.options.parameters;
    d.physics_period_ns = static_cast<uint64_t>(1e9 / p.physics_rate);
    d.steps_per_state = std::max<uint64_t>(1, std::llround(p.physics_rate / p.state_rate));
    d.max_catch_up = std::max<uint64_t>(1, uint64_t(p.physics_rate));  // 1 s of model time
    d.timer = Timer::create(d.participant, "firmware_sim_" + std::to_string(d.options.vehicle_id), d.physics_period_ns,
                            0, cpm::TimerOptions{.wait_for_start = false, .simulated_time_allowed = false});
    d.timer->start([&](uint64_t t_nominal) {
        if (stop_requested()) {
            d.timer->stop();
            return;
        }
        d.tick(t_nominal);
    });
}

std::string FirmwareSimNode::stats_json() const
{
    const auto& d = *impl_;
    const auto s = d.sim.stats();
    nlohmann::ordered_json j{{"vehicle_id", d.options.vehicle_id},
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
    return j.dump();
}

}  // namespace cpm::vehicle
