#pragma once
#include <cpm/SampleResult.hpp>
#include <cpm/vehicle/Calibration.hpp>
#include <cpm/vehicle/Controllers.hpp>
#include <cpm/vehicle/Protocol.hpp>
#include <cpm/vehicle/VehicleModel.hpp>

#include <RangeSensors.h>
#include <StopRequest.h>
#include <VehicleCommandDirect.h>
#include <VehicleCommandPathTracking.h>
#include <VehicleCommandSpeedCurvature.h>
#include <VehicleCommandTrajectory.h>
#include <VehicleState.h>

#include <array>
#include <cstdint>
#include <deque>
#include <limits>
#include <optional>
#include <string>
#include <vector>

namespace cpm::vehicle {

/// The newest valid command of each kind for this vehicle, as cpm::Reader::get_sample gives them.
struct CommandInputs
{
    SampleResult<VehicleCommandDirect> direct;
    SampleResult<VehicleCommandSpeedCurvature> speed_curvature;
    SampleResult<VehicleCommandTrajectory> trajectory;
    SampleResult<VehicleCommandPathTracking> path_tracking;
    std::optional<uint64_t> stop_request_ns;  ///< create_stamp of the newest StopRequest for this car (or all)
};

/// Which command drove a cycle.
enum class ActiveCommand { none, stopped, direct, speed_curvature, trajectory, path_tracking };
const char* to_string(ActiveCommand command);

/// Why a command cannot be obeyed: the first field that is NaN, infinite or out of range,
/// named with its value (e.g. "speed = nan is not a finite number"); empty when it can be.
/// Direct commands must lie in -1..1, speeds within ±calibration.max_speed.
std::string command_problem(const VehicleCommandDirect& command, const Calibration& calibration);
std::string command_problem(const VehicleCommandSpeedCurvature& command, const Calibration& calibration);
std::string command_problem(const VehicleCommandTrajectory& command, const Calibration& calibration);
std::string command_problem(const VehicleCommandPathTracking& command, const Calibration& calibration);

/// What the bridge noticed and did not take as given.
enum class Anomaly {
    refused_command,     ///< a command with a non-finite or out-of-range field: not obeyed
    controller_restart,  ///< the controller's tick went backwards: odometer and heading rebased
    odometer_jump,       ///< an odometer step no car can drive in that time: ignored, rebased
    battery_out_of_range,  ///< a battery reading outside the calibration's range: not published
    line_lag,            ///< the controller applies commands long after they were sent: speed feedback paused
};
constexpr size_t kAnomalyKinds = 5;
const char* to_string(Anomaly anomaly);

/// One anomaly of one cycle, with a message that names the value seen.
struct Notice
{
    Anomaly kind;
    std::string message;
};

/// What one cycle of the bridge produces.
struct BridgeCycle
{
    VehicleState state;
    RangeSensors ranges;
    CommandPacket command;
    ActiveCommand active = ActiveCommand::none;
    uint64_t measured_ns = 0;  ///< when the controller measured the state, in host time
    /// The line lags: what still waits in it answers states long gone (the AVR firmware would
    /// ignore it), so the node drops it before writing `command`.
    bool discard_queued_output = false;
    std::vector<Notice> notices;  ///< anomalies first seen in this cycle (a refused command once)
};

/// vehicle_bridge without serial port or DDS: unit conversion, pose estimate (odometer + IMU,
/// corrected by observations of the car), command selection as in cpm_lab and the on-board
/// controllers. Not thread-safe; the node calls it from its one loop.
class BridgeCore
{
public:
    BridgeCore(uint8_t vehicle_id, const Calibration& calibration, Pose start = {});

    /// One cycle for a state packet received at t_ns: the messages to publish (stamps and
    /// VehicleState::is_real not set: the caller knows the device),
    /// the command packet to send back and when the state was measured. The measurement time
    /// is the packet's tick mapped to host time through the smallest host − controller offset
    /// of the last 5 s (the least delayed packet), so a packet that waited in a buffer keeps
    /// its real, older time.
    BridgeCycle on_state_packet(const StatePacket& packet, uint64_t t_ns, const CommandInputs& commands);
    /// A state packet read at t_ns together with a newer one (it waited in the line: the line
    /// was read late): its state and ranges, measured at its own time, to publish like any
    /// other; no command answers it (`command` is unset): the newest, given to on_state_packet
    /// next, is the one answered. Call it for each older packet in order, before the newest.
    BridgeCycle on_waiting_state_packet(const StatePacket& packet, uint64_t t_ns);
    /// An observation of this car's pose taken at t_ns (e.g. VehicleObservation): the pose
    /// estimate is moved so that it agrees with it at that time.
    void on_observation(const Pose& pose, uint64_t t_ns);
    /// The serial link was reopened: the next state packet starts a new odometer baseline.
    void link_restarted();

    const Pose& pose() const { return pose_; }
    /// How many anomalies of this kind were noticed so far (a refused command counts once).
    uint64_t anomalies(Anomaly kind) const { return anomaly_counts_[size_t(kind)]; }

private:
    struct Estimate
    {
        uint64_t t_ns;
        Pose pose;
    };
    struct Actuation
    {
        double throttle = 0;   // -1..1
        double steering = 0;   // -1..1
        bool brake = true;
    };

    /// What every state packet does to the estimate, answered or not: a restart noticed, the
    /// measurement time, the pose dead-reckoned. Returns the time since the packet before (s).
    double take_in(const StatePacket& packet, uint64_t t_ns, BridgeCycle& out);
    /// The state and ranges of a packet, with the actuation in effect.
    void fill_outputs(const StatePacket& packet, double speed, const Actuation& actuation, BridgeCycle& out);
    /// Notes whether the controller's echo of the last applied command falls far behind.
    void watch_line_lag(const StatePacket& packet, std::vector<Notice>& notices);
    void dead_reckon(const StatePacket& packet, uint64_t t_ns, double tick_dt, std::vector<Notice>& notices);
    uint64_t measured_time(uint32_t tick, uint64_t received_ns);
    double plausible_battery(uint16_t battery_mv, std::vector<Notice>& notices);
    template <class T>
    bool obeyable(const SampleResult<T>& command, ActiveCommand kind, const CommandInputs& in, std::vector<Notice>& notices);
    void notice(std::vector<Notice>& notices, Anomaly kind, std::string message);
    Actuation choose(const CommandInputs& commands, uint64_t t_ns, double speed, double dt, ActiveCommand& active,
                     std::vector<Notice>& notices);
    Actuation drive(const MotionRequest& request, double speed, double dt);
    bool fresh(uint64_t age_ns, uint64_t create_ns, const CommandInputs& commands) const;
    /// The command answering the state packet of controller tick `answering`.
    CommandPacket to_packet(const Actuation& actuation, uint32_t answering);

    uint8_t vehicle_id_;
    Calibration c_;
    SpeedController speed_controller_;
    Pose pose_;
    double yaw_offset_ = 0;
    std::optional<int32_t> last_steps_;
    std::optional<uint32_t> last_tick_;
    double distance_ = 0;
    std::deque<uint32_t> answered_;  ///< the ticks the newest commands answered, oldest first
    bool line_lagging_ = false;  ///< the controller applies commands far behind the newest sent
    ActiveCommand last_active_ = ActiveCommand::none;
    Actuation last_actuation_;  ///< what the last command sent asked for (the brake at first)
    std::deque<Estimate> history_;
    uint64_t tick_epoch_ms_ = 0;  // controller ticks are 32-bit ms; they wrap after 49 days
    std::deque<std::pair<uint64_t, int64_t>> offsets_;  // (received, offset), offsets increasing
    std::array<uint64_t, kAnomalyKinds> anomaly_counts_{};
    std::array<uint64_t, 6> refused_stamp_{};  // per ActiveCommand: create_stamp of the last refused one
    double battery_v_ = std::numeric_limits<double>::quiet_NaN();  // the last plausible reading
};

}  // namespace cpm::vehicle
