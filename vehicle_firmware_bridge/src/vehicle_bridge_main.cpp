// vehicle_bridge: the car's computer between the serial line to its microcontroller and the
// lab's DDS topics (see README.md).
#include <cpm/CommandLine.hpp>
#include <cpm/Logging.hpp>
#include <cpm/Participant.hpp>
#include <cpm/Reader.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/init.hpp>
#include <cpm/stamp_message.hpp>
#include <cpm/vehicle/BridgeCore.hpp>
#include <cpm/vehicle/SerialPort.hpp>

#include <VehicleObservation.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <ctime>
#include <memory>
#include <string>
#include <thread>
#include <vector>

namespace {

const char* kHelp =
    "usage: vehicle_bridge --vehicle_id N --device PATH [--baud 115200] [--calibration FILE]\n"
    "                      [--start X,Y,YAW] [--dds_domain N]\n"
    "\n"
    "Speaks the serial protocol with vehicle N's microcontroller (real hardware or firmware_sim's\n"
    "pseudo-terminal) and the lab over DDS: every state packet (50 Hz) becomes a VehicleState on\n"
    "'vehicleState' and a RangeSensors on 'rangeSensors'; the answer is the motor and servo\n"
    "command from the freshest command for this car (Direct > SpeedCurvature > Trajectory >\n"
    "PathTracking, fresh = younger than 1 s; none fresh or a StopRequest → brake). The pose is\n"
    "dead-reckoned from odometer and IMU and corrected by 'vehicleObservation' when present.\n"
    "When the link is lost it stops publishing, logs it and reopens the device when it is back.\n"
    "It holds an exclusive lock on the device and leaves a line whose controller belongs to\n"
    "another vehicle. Samples are stamped with when the controller measured them.\n"
    "\n"
    "  --calibration FILE  units and controller gains (JSON; see vehicle_firmware_bridge/README.md)\n"
    "  --start X,Y,YAW     initial pose estimate (metres, radians) before any observation\n"
    "On SIGINT/SIGTERM it prints one JSON line of statistics and exits 0.\n";

uint64_t thread_cpu_ns()
{
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return uint64_t(ts.tv_sec) * 1'000'000'000ull + uint64_t(ts.tv_nsec);
}

uint64_t percentile(std::vector<uint64_t> values, double p)
{
    if (values.empty()) return 0;
    size_t k = std::min(values.size() - 1, size_t(p * double(values.size())));
    std::nth_element(values.begin(), values.begin() + long(k), values.end());
    return values[k];
}

/// Everything the bridge reads from and writes to the lab.
struct LabTopics
{
    explicit LabTopics(uint8_t id)
        : direct("vehicleCommandDirect", {.vehicle_id = id}),
          speed_curvature("vehicleCommandSpeedCurvature", {.vehicle_id = id}),
          trajectory("vehicleCommandTrajectory", {.vehicle_id = id}),
          path_tracking("vehicleCommandPathTracking", {.vehicle_id = id}),
          observation("vehicleObservation", {.vehicle_id = id}),
          stop("stopRequest", {.history_depth = 4})
    {
    }
    cpm::Reader<VehicleCommandDirect> direct;
    cpm::Reader<VehicleCommandSpeedCurvature> speed_curvature;
    cpm::Reader<VehicleCommandTrajectory> trajectory;
    cpm::Reader<VehicleCommandPathTracking> path_tracking;
    cpm::Reader<VehicleObservation> observation;
    cpm::ReaderAbstract<StopRequest> stop;
    cpm::Writer<VehicleState> state{"vehicleState"};
    cpm::Writer<RangeSensors> ranges{"rangeSensors"};
};

int run(int argc, char** argv)
{
    std::vector<std::string> args(argv + 1, argv + argc);
    auto parsed = cpm::cli::parse_args(
        args, {{"--vehicle_id", true}, {"--device", true}, {"--baud", true}, {"--calibration", true}, {"--start", true}},
        "vehicle_bridge");
    if (!parsed.positional.empty()) throw cpm::cli::UsageError("vehicle_bridge: unexpected argument '" + parsed.positional[0] + "'");
    if (!parsed.has("--vehicle_id")) throw cpm::cli::UsageError("vehicle_bridge: --vehicle_id is required");
    if (!parsed.has("--device")) throw cpm::cli::UsageError("vehicle_bridge: --device is required (e.g. /dev/ttyACM0)");
    auto id = static_cast<uint8_t>(cpm::cli::parse_integer("--vehicle_id", parsed.get("--vehicle_id"), 1, 255));
    const std::string device = parsed.get("--device");
    int baud = int(cpm::cli::parse_integer("--baud", parsed.get("--baud", "115200"), 1, 4'000'000));
    try {
        cpm::vehicle::SerialPort::check_baud(baud, device);
    } catch (const cpm::Error& e) {
        throw cpm::cli::UsageError(std::string("--baud: ") + e.what());
    }
    auto calibration = parsed.has("--calibration") ? cpm::vehicle::Calibration::load(parsed.get("--calibration"))
                                                   : cpm::vehicle::Calibration{};
    auto start = parsed.has("--start") ? cpm::vehicle::parse_pose("--start", parsed.get("--start")) : cpm::vehicle::Pose{};
    cpm::init(argc, argv);

    LabTopics lab(id);
    cpm::vehicle::BridgeCore core(id, calibration, start);
    cpm::cli::stop_on_signals();

    std::unique_ptr<cpm::vehicle::SerialPort> port;
    cpm::vehicle::FrameDecoder decoder;
    std::optional<uint64_t> stop_request_ns;
    uint64_t last_observation_ns = 0, last_packet_ns = 0, link_losses = 0, cycles = 0, controller_bad_crc = 0;
    uint64_t superseded = 0, foreign = 0;
    bool silent_logged = false, waiting_logged = false;
    std::vector<uint64_t> cycle_cpu_ns;

    while (!cpm::cli::stop_requested()) {
        if (!port) {
            try {
                port = std::make_unique<cpm::vehicle::SerialPort>(device, baud);
                CPM_LOG_INFO("vehicle %u: serial link open on %s%s", unsigned(id), device.c_str(),
                             port->is_pseudo_terminal() ? " (pseudo-terminal: simulated car)" : "");
                core.link_restarted();
                decoder = cpm::vehicle::FrameDecoder{};
                last_packet_ns = cpm::get_time_ns();
                silent_logged = waiting_logged = false;
            } catch (const cpm::vehicle::DeviceUnavailable& e) {
                // Not there yet, unplugged or busy: keep trying. Any other error is the user's to fix.
                if (!waiting_logged) CPM_LOG_WARN("vehicle %u: %s; retrying every 200 ms", unsigned(id), e.what());
                waiting_logged = true;
                std::this_thread::sleep_for(std::chrono::milliseconds(200));
                continue;
            }
        }
        uint8_t buffer[256];
        long n = port->read_some(buffer, sizeof buffer, 100);
        uint64_t t_received = cpm::get_time_ns();
        if (n < 0) {
            ++link_losses;
            CPM_LOG_ERROR("vehicle %u: serial link to %s lost; no fresh state until it is back", unsigned(id), device.c_str());
            port.reset();
            continue;
        }
        if (n == 0) {
            if (!silent_logged && t_received - last_packet_ns > 200'000'000ull) {
                CPM_LOG_WARN("vehicle %u: no state packet from the controller for 200 ms", unsigned(id));
                silent_logged = true;
            }
            continue;
        }
        for (const auto& s : lab.stop.take()) {
            if (s.vehicle_id() != 0 && s.vehicle_id() != id) continue;
            stop_request_ns = std::max(stop_request_ns.value_or(0), s.header().create_stamp().nanoseconds());
        }
        // Only the newest state counts: older ones in the same read waited in a buffer.
        std::optional<cpm::vehicle::StatePacket> newest;
        decoder.feed(buffer, size_t(n), [&](const cpm::vehicle::Packet& packet) {
            if (const auto* state = std::get_if<cpm::vehicle::StatePacket>(&packet)) {
                if (newest) ++superseded;
                newest = *state;
            }
        });
        if (!newest) continue;
        if (newest->vehicle_id != id) {
            ++foreign;
            CPM_LOG_ERROR("vehicle %u: the controller on %s belongs to vehicle %u; leaving the line", unsigned(id),
                          device.c_str(), unsigned(newest->vehicle_id));
            port.reset();
            std::this_thread::sleep_for(std::chrono::milliseconds(200));
            continue;
        }
        const uint64_t cpu0 = thread_cpu_ns();
        if (silent_logged) CPM_LOG_INFO("vehicle %u: state packets again", unsigned(id));
        silent_logged = false;
        last_packet_ns = t_received;
        if (newest->status & cpm::vehicle::kStatusBadCrc) ++controller_bad_crc;

        auto observation = lab.observation.get_sample(t_received);
        uint64_t observed_ns = observation.sample.header().create_stamp().nanoseconds();
        if (observation.valid && observed_ns > last_observation_ns) {
            last_observation_ns = observed_ns;
            const auto& p = observation.sample.pose();
            core.on_observation({p.x(), p.y(), p.yaw()}, observed_ns);
        }
        cpm::vehicle::CommandInputs inputs{lab.direct.get_sample(t_received), lab.speed_curvature.get_sample(t_received),
                                           lab.trajectory.get_sample(t_received), lab.path_tracking.get_sample(t_received),
                                           stop_request_ns};
        auto cycle = core.on_state_packet(*newest, t_received, inputs);
        auto frame = cpm::vehicle::encode_frame(cycle.command);
        port->write_all(frame.data(), frame.size());

        // create = when the controller measured; valid_after = when it is published plus the
        // expected delivery, so a sample's age says how old the measurement really is.
        const uint64_t t_publish = cpm::get_time_ns();
        const uint64_t delay = t_publish - std::min(cycle.measured_ns, t_publish) + uint64_t(calibration.publish_delay * 1e9);
        cycle.state.is_real(!port->is_pseudo_terminal());
        cpm::stamp_message(cycle.state, cycle.measured_ns, delay);
        cpm::stamp_message(cycle.ranges, cycle.measured_ns, delay);
        lab.state.write(cycle.state);
        lab.ranges.write(cycle.ranges);
        ++cycles;
        if (cycle_cpu_ns.size() < 1'000'000) cycle_cpu_ns.push_back(thread_cpu_ns() - cpu0);
    }

    const auto& e = decoder.errors();
    std::printf("{\"vehicle_id\": %u, \"cycles\": %llu, \"cycle_cpu_us_p50\": %.1f, \"cycle_cpu_us_p99\": %.1f, "
                "\"link_losses\": %llu, \"superseded_states\": %llu, \"foreign_controller\": %llu, "
                "\"controller_reported_bad_crc\": %llu, \"decoder_errors\": %llu}\n",
                unsigned(id), (unsigned long long)cycles, percentile(cycle_cpu_ns, 0.5) / 1e3,
                percentile(cycle_cpu_ns, 0.99) / 1e3, (unsigned long long)link_losses, (unsigned long long)superseded,
                (unsigned long long)foreign, (unsigned long long)controller_bad_crc, (unsigned long long)e.total());
    std::fflush(stdout);
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "vehicle_bridge", kHelp, run); }
