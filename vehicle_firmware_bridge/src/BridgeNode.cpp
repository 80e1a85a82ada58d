#include <cpm/topics.hpp>
#include <cpm/vehicle/BridgeNode.hpp>

#include <cpm/LogThrottle.hpp>
#include <cpm/Logging.hpp>
#include <cpm/Reader.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/percentile.hpp>
#include <cpm/stamp_message.hpp>
#include <cpm/vehicle/SerialPort.hpp>

#include <VehicleObservation.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <ctime>
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

/// Everything the bridge reads from and writes to the lab.
struct LabTopics
{
    explicit LabTopics(uint8_t id)
        : direct(topics::vehicle_command_direct.name, topics::vehicle_command_direct.reader_for(id)),
          speed_curvature(topics::vehicle_command_speed_curvature.name, topics::vehicle_command_speed_curvature.reader_for(id)),
          trajectory(topics::vehicle_command_trajectory.name, topics::vehicle_command_trajectory.reader_for(id)),
          path_tracking(topics::vehicle_command_path_tracking.name, topics::vehicle_command_path_tracking.reader_for(id)),
          observation(topics::vehicle_observation.name, topics::vehicle_observation.reader_for(id)),
          stop(topics::stop_request.name, topics::stop_request.reader)
    {
    }
    Reader<VehicleCommandDirect> direct;
    Reader<VehicleCommandSpeedCurvature> speed_curvature;
    Reader<VehicleCommandTrajectory> trajectory;
    Reader<VehicleCommandPathTracking> path_tracking;
    Reader<VehicleObservation> observation;
    ReaderAbstract<StopRequest> stop;
    Writer<VehicleState> state{topics::vehicle_state.name, topics::vehicle_state.writer};
    Writer<RangeSensors> ranges{topics::range_sensors.name, topics::range_sensors.writer};
};

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
                             {"decoder_errors", decoder_errors}};
    for (size_t k = 0; k < kAnomalyKinds; ++k) j[to_string(Anomaly(k))] = anomalies[k];
    return j.dump();
}

struct BridgeNode::Impl
{
    explicit Impl(BridgeNodeOptions o) : options(std::move(o)), lab(options.vehicle_id),
        core(options.vehicle_id, options.calibration, options.start) {}

    void run(const std::function<bool()>& stop_requested);
    bool open_line();
    void cycle(const StatePacket& packet, uint64_t t_received);
    void report(const std::vector<Notice>& notices);

    BridgeNodeOptions options;
    LabTopics lab;
    BridgeCore core;
    std::unique_ptr<SerialPort> port;
    FrameDecoder decoder;
    std::optional<uint64_t> stop_request_ns;
    uint64_t last_observation_ns = 0, last_packet_ns = 0;
    int foreign_in_a_row = 0;
    bool silent_logged = false, waiting_logged = false;
    std::vector<uint64_t> cycle_cpu_ns;
    BridgeNodeStats stats;
    LogThrottle throttles[kAnomalyKinds];
    LogThrottle foreign_throttle, leave_throttle{10'000'000'000ull};
};

bool BridgeNode::Impl::open_line()
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

void BridgeNode::Impl::report(const std::vector<Notice>& notices)
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

void BridgeNode::Impl::cycle(const StatePacket& packet, uint64_t t_received)
{
    const uint64_t cpu0 = thread_cpu_ns();
    if (silent_logged) CPM_LOG_INFO("vehicle %u: state packets again", unsigned(options.vehicle_id));
    silent_logged = false;
    last_packet_ns = t_received;
    if (packet.status & kStatusBadCrc) ++stats.controller_reported_bad_crc;

    auto observation = lab.observation.get_sample(t_received);
    uint64_t observed_ns = observation.sample.header().create_stamp().nanoseconds();
    if (observation.valid && observed_ns > last_observation_ns) {
        last_observation_ns = observed_ns;
        const auto& p = observation.sample.pose();
        core.on_observation({p.x(), p.y(), p.yaw()}, observed_ns);
    }
    CommandInputs inputs{lab.direct.get_sample(t_received), lab.speed_curvature.get_sample(t_received),
                         lab.trajectory.get_sample(t_received), lab.path_tracking.get_sample(t_received),
                         stop_request_ns};
    auto out = core.on_state_packet(packet, t_received, inputs);
    auto frame = encode_frame(out.command);
    port->write_all(frame.data(), frame.size());
    report(out.notices);

    // create = when the controller measured; valid_after = when it is published plus the
    // expected delivery, so a sample's age says how old the measurement really is.
    const uint64_t t_publish = get_time_ns();
    const uint64_t delay =
        t_publish - std::min(out.measured_ns, t_publish) + uint64_t(options.calibration.publish_delay * 1e9);
    out.state.is_real(!port->is_pseudo_terminal());
    stamp_message(out.state, out.measured_ns, delay);
    stamp_message(out.ranges, out.measured_ns, delay);
    (void)lab.state.write(out.state);
    (void)lab.ranges.write(out.ranges);
    ++stats.cycles;
    if (cycle_cpu_ns.size() < 1'000'000) cycle_cpu_ns.push_back(thread_cpu_ns() - cpu0);
}

void BridgeNode::Impl::run(const std::function<bool()>& stop_requested)
{
    const unsigned id = options.vehicle_id;
    while (!stop_requested()) {
        if (!port && !open_line()) {
            std::this_thread::sleep_for(std::chrono::milliseconds(200));
            continue;
        }
        uint8_t buffer[256];
        long n = port->read_some(buffer, sizeof buffer, 100);
        uint64_t t_received = get_time_ns();
        if (n < 0) {
            ++stats.link_losses;
            stats.decoder_errors += decoder.errors().total();
            CPM_LOG_ERROR("vehicle %u: serial link to %s lost; no fresh state until it is back", id, options.device.c_str());
            port.reset();
            continue;
        }
        if (n == 0) {
            if (!silent_logged && t_received - last_packet_ns > 200'000'000ull) {
                CPM_LOG_WARN("vehicle %u: no state packet from the controller for 200 ms", id);
                silent_logged = true;
            }
            continue;
        }
        for (const auto& s : lab.stop.take()) {
            if (s.vehicle_id() != 0 && s.vehicle_id() != id) continue;
            stop_request_ns = std::max(stop_request_ns.value_or(0), s.header().create_stamp().nanoseconds());
        }
        // Only the newest of this car's states counts: older ones in the same read waited in a
        // buffer. Another car's packets are never used.
        std::optional<StatePacket> newest;
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
            if (newest) ++stats.superseded_states;
            newest = *state;
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
            continue;
        }
        if (newest) cycle(*newest, t_received);
    }
}

BridgeNode::BridgeNode(BridgeNodeOptions options) : impl_(std::make_unique<Impl>(std::move(options))) {}
BridgeNode::~BridgeNode() = default;

void BridgeNode::run(const std::function<bool()>& stop_requested) { impl_->run(stop_requested); }

BridgeNodeStats BridgeNode::stats() const
{
    BridgeNodeStats s = impl_->stats;
    s.vehicle_id = impl_->options.vehicle_id;
    s.cycle_cpu_us_p50 = double(percentile(impl_->cycle_cpu_ns, 0.5)) / 1e3;
    s.cycle_cpu_us_p99 = double(percentile(impl_->cycle_cpu_ns, 0.99)) / 1e3;
    if (impl_->port) s.decoder_errors += impl_->decoder.errors().total();
    for (size_t k = 0; k < kAnomalyKinds; ++k) s.anomalies[k] = impl_->core.anomalies(Anomaly(k));
    return s;
}

}  // namespace cpm::vehicle
