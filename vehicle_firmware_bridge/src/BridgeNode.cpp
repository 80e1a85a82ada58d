#include <cpm/topics.hpp>
#include <cpm/vehicle/BridgeNode.hpp>

#include <cpm/LogThrottle.hpp>
#include <cpm/AsyncReader.hpp>
#include <cpm/Error.hpp>
#include <cpm/Logging.hpp>
#include <cpm/Timer.hpp>
#include <cpm/init.hpp>
#include <cpm/MultiVehicleReader.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/timer_ids.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/stamp_message.hpp>
#include <cpm/vehicle/SerialPort.hpp>

#include "WriterThread.hpp"

#include <VehicleObservation.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <atomic>
#include <exception>
#include <chrono>
#include <ctime>
#include <map>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

namespace cpm::vehicle {

namespace {

uint64_t thread_cpu_ns()
{
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return uint64_t(ts.tv_sec) * 1'000'000'000ull + uint64_t(ts.tv_nsec);
}

/// Everything the bridge's cars read from and write to the lab: one reader per topic for all
/// of them (each car picks its own samples), one writer per topic.
struct LabTopics
{
    explicit LabTopics(const std::vector<uint8_t>& ids)
        : direct(topics::vehicle_command_direct.name, ids, topics::vehicle_command_direct.reader),
          speed_curvature(topics::vehicle_command_speed_curvature.name, ids, topics::vehicle_command_speed_curvature.reader),
          trajectory(topics::vehicle_command_trajectory.name, ids, topics::vehicle_command_trajectory.reader),
          path_tracking(topics::vehicle_command_path_tracking.name, ids, topics::vehicle_command_path_tracking.reader),
          observation(topics::vehicle_observation.name, ids, topics::vehicle_observation.reader)
    {
    }
    /// create_stamp of the newest StopRequest for this car or for all (vehicle_id 0).
    std::optional<uint64_t> stop_request_ns(uint8_t id)
    {
        std::lock_guard<std::mutex> lock(stop_mutex);
        auto all = stop_requests[0], mine = stop_requests[id];
        if (!all) return mine;
        if (!mine) return all;
        return std::max(*all, *mine);
    }
    MultiVehicleReader<VehicleCommandDirect> direct;
    MultiVehicleReader<VehicleCommandSpeedCurvature> speed_curvature;
    MultiVehicleReader<VehicleCommandTrajectory> trajectory;
    MultiVehicleReader<VehicleCommandPathTracking> path_tracking;
    MultiVehicleReader<VehicleObservation> observation;
    std::mutex stop_mutex;
    std::map<uint8_t, std::optional<uint64_t>> stop_requests;
    /// StopRequests come by the reader's callback on the DDS thread that receives them: the
    /// serial loop (a real-time thread) never calls into Fast DDS, whose reader lock a DDS thread
    /// of normal priority may hold (matching the writers of processes starting elsewhere).
    AsyncReader<StopRequest> stop{[this](std::vector<StopRequest>& batch) { on_stops(batch); }, topics::stop_request.name,
                                  topics::stop_request.reader.on_dds_thread()};
    void on_stops(const std::vector<StopRequest>& batch)
    {
        std::lock_guard<std::mutex> lock(stop_mutex);
        for (const auto& s : batch) {
            auto& newest = stop_requests[s.vehicle_id()];
            newest = std::max(newest.value_or(0), s.header().create_stamp().nanoseconds());
        }
    }
    Writer<VehicleState> state{topics::vehicle_state.name, topics::vehicle_state.writer};
    Writer<RangeSensors> ranges{topics::range_sensors.name, topics::range_sensors.writer};
    /// In real time the serial loops hand their samples to threads of their own: a stalled DDS
    /// write must not hold up the next command (the car's watchdog would brake it).
    WriterThread<VehicleState> state_out{state, topics::vehicle_state.name, 256, !init_settings().simulated_time};
    WriterThread<RangeSensors> ranges_out{ranges, topics::range_sensors.name, 256, !init_settings().simulated_time};
};

std::vector<uint8_t> checked_ids(const std::vector<BridgeNodeOptions>& cars)
{
    if (cars.empty()) throw Error("vehicle_bridge: no car to serve");
    std::vector<uint8_t> ids;
    for (const auto& c : cars) {
        if (std::find(ids.begin(), ids.end(), c.vehicle_id) != ids.end())
            throw Error("vehicle_bridge: vehicle " + std::to_string(c.vehicle_id) + " is given twice");
        ids.push_back(c.vehicle_id);
    }
    return ids;
}

}  // namespace

std::string BridgeNodeStats::to_json() const
{
    nlohmann::ordered_json j{{"vehicle_id", vehicle_id},
                             {"cycles", cycles},
                             {"cycle_cpu_us_p50", cycle_cpu_us_p50},
                             {"cycle_cpu_us_p99", cycle_cpu_us_p99},
                             {"link_losses", link_losses},
                             {"superseded_states", superseded_states},
                             {"foreign_packets", foreign_packets},
                             {"foreign_controller", foreign_controller},
                             {"controller_reported_bad_crc", controller_reported_bad_crc},
                             {"decoder_errors", decoder_errors},
                             {"output_discards", output_discards},
                             {"missed_ticks", missed_ticks}};
    for (size_t k = 0; k < kAnomalyKinds; ++k) j[to_string(Anomaly(k))] = anomalies[k];
    return j.dump();
}

namespace {

/// One car's loop: its serial line, its BridgeCore, its statistics.
struct BridgeCar
{
    BridgeCar(BridgeNodeOptions o, LabTopics& topics) : options(std::move(o)), lab(topics),
        core(options.vehicle_id, options.calibration, options.start) {}

    /// Real time: serves the line until stop_requested().
    void run(const std::function<bool()>& stop_requested);
    /// Simulated time, once per tick: answers the packet the controller just sent.
    void serve_tick(const std::function<bool()>& stop_requested);
    /// Reads the open line once (waiting up to timeout_ms) and answers the newest of this car's
    /// state packets in it (the older ones in the same read are published, not answered); true
    /// when it answered one.
    bool serve(int timeout_ms, const std::function<bool()>& stop_requested);
    bool open_line();
    void cycle(const StatePacket& packet, uint64_t t_received);
    /// Stamps and publishes a cycle's state and ranges (the controller measured them at
    /// measured_ns; valid once delivered).
    void publish(BridgeCycle& out);
    void report(const std::vector<Notice>& notices);
    BridgeNodeStats final_stats() const;

    BridgeNodeOptions options;
    LabTopics& lab;
    BridgeCore core;
    std::unique_ptr<SerialPort> port;
    FrameDecoder decoder;
    /// This car's state packets of one read, in order (room for more than a read can hold:
    /// the loop never allocates).
    std::vector<StatePacket> read_states = [] {
        std::vector<StatePacket> v;
        v.reserve(64);
        return v;
    }();
    uint64_t last_observation_ns = 0, last_packet_ns = 0;
    int foreign_in_a_row = 0;
    bool silent_logged = false, waiting_logged = false;
    bool controller_silent = false;  ///< simulated time: the last tick's packet never came
    // The CPU time of each cycle, in 1 µs bins up to 20 ms (the last bin: longer): its median and
    // p99 in memory that does not grow with the run (a vector of every cycle grew the bridge of
    // ten cars by 2.4 MB in ten minutes, bench_soak).
    static constexpr size_t kCycleBins = 20'000;
    std::vector<uint64_t> cycle_cpu_us = std::vector<uint64_t>(kCycleBins, 0);
    uint64_t cycles_timed = 0;
    double cycle_cpu_percentile_us(double p) const
    {
        const uint64_t rank = static_cast<uint64_t>(p * double(cycles_timed));
        uint64_t seen = 0;
        for (size_t us = 0; us < kCycleBins; ++us)
            if ((seen += cycle_cpu_us[us]) > rank) return double(us) + 0.5;
        return double(kCycleBins);
    }
    BridgeNodeStats stats;
    LogThrottle throttles[kAnomalyKinds];
    LogThrottle foreign_throttle, superseded_throttle, leave_throttle{10'000'000'000ull};
};

}  // namespace

bool BridgeCar::open_line()
{
    const unsigned id = options.vehicle_id;
    try {
        port = std::make_unique<SerialPort>(options.device, options.baud);
    } catch (const DeviceUnavailable& e) {
        // Not there yet, unplugged or busy: keep trying. Any other error is the user's to fix.
        if (!waiting_logged) CPM_LOG_WARN("vehicle %u: %s; retrying every 200 ms", id, e.what());
        waiting_logged = true;
        return false;
    }
    CPM_LOG_INFO("vehicle %u: serial link open on %s%s", id, options.device.c_str(),
                 port->is_pseudo_terminal() ? " (pseudo-terminal: simulated car)" : "");
    core.link_restarted();
    decoder = FrameDecoder{};
    last_packet_ns = get_time_ns();
    silent_logged = waiting_logged = false;
    foreign_in_a_row = 0;
    return true;
}

void BridgeCar::report(const std::vector<Notice>& notices)
{
    for (const auto& n : notices) {
        uint64_t held = 0;
        if (!throttles[size_t(n.kind)].allow(get_time_ns(), held)) continue;
        if (held > 0) {
            CPM_LOG_WARN("vehicle %u: %s (and %llu more like it since the last report)", unsigned(options.vehicle_id),
                         n.message.c_str(), (unsigned long long)held);
        } else {
            CPM_LOG_WARN("vehicle %u: %s", unsigned(options.vehicle_id), n.message.c_str());
        }
    }
}

void BridgeCar::cycle(const StatePacket& packet, uint64_t t_received)
{
    const uint64_t cpu0 = thread_cpu_ns();
    if (silent_logged) CPM_LOG_INFO("vehicle %u: state packets again", unsigned(options.vehicle_id));
    silent_logged = false;
    last_packet_ns = t_received;
    if (packet.status & kStatusBadCrc) ++stats.controller_reported_bad_crc;

    const uint8_t id = options.vehicle_id;
    // On the simulated clock the car's simulator writes its observation in the bridge's own step:
    // the bridge takes the one before (its age is made up from the odometry), never one whose
    // arrival races the tick.
    auto observation = lab.observation.get_sample(id, init_settings().simulated_time ? timer_ids::simulated_read_before_step(t_received) : t_received);
    uint64_t observed_ns = observation.sample.header().create_stamp().nanoseconds();
    if (observation.valid && observed_ns > last_observation_ns) {
        last_observation_ns = observed_ns;
        const auto& p = observation.sample.pose();
        core.on_observation({p.x(), p.y(), p.yaw()}, observed_ns);
    }
    CommandInputs inputs{lab.direct.get_sample(id, t_received), lab.speed_curvature.get_sample(id, t_received),
                         lab.trajectory.get_sample(id, t_received), lab.path_tracking.get_sample(id, t_received),
                         lab.stop_request_ns(id)};
    auto out = core.on_state_packet(packet, t_received, inputs);
    auto frame = encode_frame(out.command);
    if (out.discard_queued_output && port->discard_output()) ++stats.output_discards;
    port->write_all(frame.data(), frame.size());
    report(out.notices);

    publish(out);
    ++stats.cycles;
    ++cycle_cpu_us[std::min<uint64_t>((thread_cpu_ns() - cpu0) / 1000, kCycleBins - 1)];
    ++cycles_timed;
}

void BridgeCar::publish(BridgeCycle& out)
{
    // create = when the controller measured; valid_after = when it is published plus the
    // expected delivery, so a sample's age says how old the measurement really is.
    const uint64_t t_publish = get_time_ns();
    const uint64_t delay =
        t_publish - std::min(out.measured_ns, t_publish) + uint64_t(options.calibration.publish_delay * 1e9);
    out.state.is_real(!port->is_pseudo_terminal());
    stamp_message(out.state, out.measured_ns, delay);
    stamp_message(out.ranges, out.measured_ns, delay);
    lab.state_out.write(out.state);
    lab.ranges_out.write(out.ranges);
}

void BridgeCar::run(const std::function<bool()>& stop_requested)
{
    const RealtimeThread realtime(init_settings().realtime, realtime_priority::serial_loop,
                                  "vehicle " + std::to_string(options.vehicle_id) + "'s serial loop");
    while (!stop_requested()) {
        if (!port && !open_line()) {
            std::this_thread::sleep_for(std::chrono::milliseconds(200));
            continue;
        }
        serve(100, stop_requested);
    }
}

void BridgeCar::serve_tick(const std::function<bool()>& stop_requested)
{
    // Simulated time: the controller writes its packet in this very step (both timers tick in
    // it), and a pty hands bytes over asynchronously: wait for it,
    // up to kSimulatedPacketWait of real time (100 ms ran out on a loaded machine, and the run
    // then differed from the one before). A controller that stayed silent is not waited for
    // again until it sends once more: a run without it goes on at its pace.
    if (!port && !open_line()) return;
    const auto wait = controller_silent ? std::chrono::milliseconds(0) : kSimulatedPacketWait;
    const auto deadline = std::chrono::steady_clock::now() + wait;
    for (;;) {
        if (!port || stop_requested()) return;
        const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
        if (serve(int(std::max<long>(left.count(), 0)), stop_requested)) {
            controller_silent = false;
            return;
        }
        if (left.count() <= 0) break;
    }
    ++stats.missed_ticks;
    if (!controller_silent) {
        CPM_LOG_WARN("vehicle %u: no state packet for lab time %.3f s within %lld ms of real time; not waiting again until one "
                     "comes (the run will not repeat exactly)",
                     unsigned(options.vehicle_id), double(get_time_ns()) * 1e-9, (long long)kSimulatedPacketWait.count());
    }
    controller_silent = true;
}

bool BridgeCar::serve(int timeout_ms, const std::function<bool()>& stop_requested)
{
    const unsigned id = options.vehicle_id;
    {
        uint8_t buffer[256];
        long n = port->read_some(buffer, sizeof buffer, timeout_ms);
        uint64_t t_received = get_time_ns();
        if (n < 0) {
            ++stats.link_losses;
            stats.decoder_errors += decoder.errors().total();
            CPM_LOG_ERROR("vehicle %u: serial link to %s lost; no fresh state until it is back", id, options.device.c_str());
            port.reset();
            return false;
        }
        if (n == 0) {
            if (!silent_logged && t_received - last_packet_ns > 200'000'000ull) {
                CPM_LOG_WARN("vehicle %u: no state packet from the controller for 200 ms", id);
                silent_logged = true;
            }
            return false;
        }
        // The newest of this car's states is answered; older ones in the same read waited in a
        // buffer (measurements all the same: published, at their own times). Another car's
        // packets are never used.
        read_states.clear();
        std::optional<uint8_t> foreign_id;
        decoder.feed(buffer, size_t(n), [&](const Packet& packet) {
            const auto* state = std::get_if<StatePacket>(&packet);
            if (!state) return;
            if (state->vehicle_id != id) {
                ++stats.foreign_packets;
                ++foreign_in_a_row;
                foreign_id = state->vehicle_id;
                return;
            }
            foreign_in_a_row = 0;
            read_states.push_back(*state);
        });
        if (foreign_id && foreign_in_a_row < options.foreign_packets_to_leave) {
            uint64_t held = 0;
            if (foreign_throttle.allow(t_received, held))
                CPM_LOG_WARN("vehicle %u: ignored a state packet from the controller of vehicle %u on %s (%llu more "
                             "since the last report)",
                             id, unsigned(*foreign_id), options.device.c_str(), (unsigned long long)held);
        }
        if (foreign_in_a_row >= options.foreign_packets_to_leave) {
            ++stats.foreign_controller;
            uint64_t held = 0;
            if (leave_throttle.allow(t_received, held))
                CPM_LOG_ERROR("vehicle %u: the controller on %s belongs to vehicle %u; leaving the line, trying again "
                              "every %d ms (left %llu times before)",
                              id, options.device.c_str(), unsigned(foreign_id.value_or(0)), options.foreign_retry_ms,
                              (unsigned long long)held);
            stats.decoder_errors += decoder.errors().total();
            port.reset();
            for (int waited = 0; waited < options.foreign_retry_ms && !stop_requested(); waited += 100)
                std::this_thread::sleep_for(std::chrono::milliseconds(100));
            return false;
        }
        if (read_states.empty()) return false;
        const auto superseded_in_read = unsigned(read_states.size() - 1);
        stats.superseded_states += superseded_in_read;
        if (superseded_in_read > 0) {
            // Late, not lost: the loop read the line late (a busy machine, the kernel's worker
            // that hands a pseudo-terminal's bytes over, a stalled thread). Said, not only counted.
            uint64_t held = 0;
            if (superseded_throttle.allow(t_received, held))
                CPM_LOG_WARN("vehicle %u: %u state packet(s) waited in the line (published; only the newest was "
                             "answered): the serial loop read late (%llu more reads like it since the last report)",
                             id, superseded_in_read, (unsigned long long)held);
        }
        for (size_t k = 0; k + 1 < read_states.size(); ++k) {
            auto waited = core.on_waiting_state_packet(read_states[k], t_received);
            report(waited.notices);
            publish(waited);
        }
        cycle(read_states.back(), t_received);
        return true;
    }
}

BridgeNodeStats BridgeCar::final_stats() const
{
    BridgeNodeStats s = stats;
    s.vehicle_id = options.vehicle_id;
    s.cycle_cpu_us_p50 = cycles_timed ? cycle_cpu_percentile_us(0.5) : 0;
    s.cycle_cpu_us_p99 = cycles_timed ? cycle_cpu_percentile_us(0.99) : 0;
    if (port) s.decoder_errors += decoder.errors().total();
    for (size_t k = 0; k < kAnomalyKinds; ++k) s.anomalies[k] = core.anomalies(Anomaly(k));
    return s;
}

struct BridgeNode::Impl
{
    explicit Impl(std::vector<BridgeNodeOptions> options) : lab(checked_ids(options))
    {
        for (auto& o : options) cars.push_back(std::make_unique<BridgeCar>(std::move(o), lab));
        Logging::instance().connect();  // the serial loops' first message must not create DDS entities
    }
    LabTopics lab;
    std::vector<std::unique_ptr<BridgeCar>> cars;
};

BridgeNode::BridgeNode(BridgeNodeOptions options) : BridgeNode(std::vector<BridgeNodeOptions>{std::move(options)}) {}
BridgeNode::BridgeNode(std::vector<BridgeNodeOptions> cars) : impl_(std::make_unique<Impl>(std::move(cars))) {}
BridgeNode::~BridgeNode() = default;

std::string BridgeNode::timer_name(uint8_t first_vehicle_id) { return timer_ids::vehicle_bridge(first_vehicle_id); }

void BridgeNode::run(const std::function<bool()>& stop_requested)
{
    if (init_settings().simulated_time) {
        // One tick per state packet, in the controllers' step on the lab's clock (1 ms into the
        // period): each waits for its packet of that step and answers it before the next.
        auto& cars = impl_->cars;
        // The bridge joins the clock once every line is open, as a node joins it once its inputs
        // have writers: opening flushes a line, and the state packet the controller sent at lab
        // time 0 must not go with it (that cost the bridge's first tick 100 ms of waiting, and
        // the controller's next one 100 ms waiting for an answer).
        for (auto& car : cars) {
            while (!car->open_line()) {
                if (stop_requested()) return;
                std::this_thread::sleep_for(std::chrono::milliseconds(200));
            }
        }
        auto timer = Timer::create(timer_name(cars[0]->options.vehicle_id), cars[0]->options.simulated_state_period_ns,
                                   timer_ids::kSimulatedCarOffset_ns,
                                   TimerOptions{.wait_for_start = false, .simulated_time_allowed = true});
        timer->run_until(stop_requested, [&](uint64_t) {
            for (auto& car : cars) car->serve_tick(stop_requested);
        });
        return;
    }
    if (impl_->cars.size() == 1) return impl_->cars[0]->run(stop_requested);
    // A loop per car. One that fails (a device that is not a terminal) stops the others and
    // its error is the node's, as with one car.
    std::mutex mutex;
    std::exception_ptr failure;
    std::atomic<bool> failed{false};
    const std::function<bool()> stop_all = [&] { return failed.load() || stop_requested(); };
    std::vector<std::thread> threads;
    for (auto& car : impl_->cars) {
        threads.emplace_back([&] {
            try {
                car->run(stop_all);
            } catch (...) {
                std::lock_guard<std::mutex> lock(mutex);
                if (!failure) failure = std::current_exception();
                failed = true;
            }
        });
    }
    for (auto& t : threads) t.join();
    if (failure) std::rethrow_exception(failure);
}

BridgeNodeStats BridgeNode::stats() const { return impl_->cars[0]->final_stats(); }

std::vector<BridgeNodeStats> BridgeNode::all_stats() const
{
    std::vector<BridgeNodeStats> out;
    for (const auto& car : impl_->cars) out.push_back(car->final_stats());
    return out;
}

}  // namespace cpm::vehicle
