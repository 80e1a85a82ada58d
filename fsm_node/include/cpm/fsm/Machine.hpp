#pragma once
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

/// The state-machine engine of fsm_node (no DDS inside): states are driving functions,
/// transitions are events; the machine is data, loaded and checked by cpm::fsm::load_*.
namespace cpm::fsm {

/// One ArUco marker as the car sees it: pose in the car frame (x forward, y left), metres/rad.
struct MarkerSighting
{
    int id = 0;
    double x = 0, y = 0, yaw = 0;
    double distance = 0;
};

/// What a tick sees of the car. Units: s, m, m/s, rad.
struct Inputs
{
    double t = 0;              ///< time, s (monotone)
    double odometer = 0;       ///< distance driven, m (hall sensor)
    double yaw = 0;            ///< heading, rad (IMU)
    double speed = 0;          ///< m/s
    double front = 0, left = 0, right = 0;  ///< ultrasonic ranges, m
    std::vector<MarkerSighting> markers;
};

/// What a tick asks of the car: VehicleCommandDirect's throttle and steering (-1..1, + = left).
struct Output
{
    double throttle = 0;
    double steering = 0;
    bool brake = false;  ///< Stop: brake, not coast (throttle and steering are 0)
};

/// A point (and heading) in the car's frame at the moment a transition fires; for a gate, the
/// ids of its markers (-1: any), so that the next state can keep looking at it.
struct Target
{
    double x = 0, y = 0, yaw = 0;
    int marker_a = -1, marker_b = -1;
};

/// A driving function. tick() runs while the state is active.
class State
{
public:
    State(int id, std::string type) : id_(id), type_(std::move(type)) {}
    virtual ~State() = default;
    virtual void on_enter(const Inputs& in) { entered_odometer_ = in.odometer; entered_t_ = in.t; }
    virtual Output tick(const Inputs& in, double dt) = 0;
    virtual void on_exit() {}
    /// Finishable states report when they are done (the `Finished` transition).
    virtual bool can_finish() const { return false; }
    virtual bool finished() const { return false; }
    /// Targetable states take a target from a transition (`ArucoGateFound`).
    virtual bool can_take_target() const { return false; }
    virtual void set_target(const Target&) {}

    int id() const { return id_; }
    const std::string& type() const { return type_; }
    bool is_final() const { return final_; }
    void set_final(bool f) { final_ = f; }
    double distance_since_entry(const Inputs& in) const { return in.odometer - entered_odometer_; }
    double time_since_entry(const Inputs& in) const { return in.t - entered_t_; }

private:
    int id_;
    std::string type_;
    bool final_ = false;
    double entered_odometer_ = 0, entered_t_ = 0;
};

/// An event that moves the machine from its owner state to its target state.
class Transition
{
public:
    Transition(int id, std::string type, int from, int to) : id_(id), type_(std::move(type)), from_(from), to_(to) {}
    virtual ~Transition() = default;
    /// Called when the owner is entered (resets counters).
    virtual void reset() {}
    /// Whether it fires now, after the owner ticked.
    virtual bool fires(const Inputs& in, const State& owner) = 0;
    /// A target for the next state (only ArucoGateFound has one).
    virtual std::optional<Target> target() const { return std::nullopt; }

    int id() const { return id_; }
    const std::string& type() const { return type_; }
    int from() const { return from_; }
    int to() const { return to_; }

private:
    int id_;
    std::string type_;
    int from_, to_;
};

/// States, transitions and the active state. Each tick: the active state's tick() computes the
/// output, then its transitions are checked in file order and the first that fires switches
/// states (on_exit of the old, on_enter of the new, a target passed on). Not thread-safe.
class Machine
{
public:
    Machine(std::vector<std::unique_ptr<State>> states, std::vector<std::unique_ptr<Transition>> transitions, int root);

    /// Enters the root state (also done by the first tick).
    void start(const Inputs& in);
    Output tick(const Inputs& in, double dt);

    const State& active() const { return *active_; }
    /// Id of the last transition that fired, -1 before any.
    int last_transition() const { return last_transition_; }
    /// Time (Inputs::t) at which the active state was entered.
    double entered_t() const { return entered_t_; }
    bool in_final_state() const { return active_->is_final(); }
    const std::vector<std::unique_ptr<State>>& states() const { return states_; }
    const std::vector<std::unique_ptr<Transition>>& transitions() const { return transitions_; }
    int root() const { return root_; }

private:
    void enter(State* state, const Inputs& in);
    State* state_by_id(int id) const;

    std::vector<std::unique_ptr<State>> states_;
    std::vector<std::unique_ptr<Transition>> transitions_;
    int root_;
    State* active_ = nullptr;
    bool started_ = false;
    int last_transition_ = -1;
    double entered_t_ = 0;
};

/// Whether a state or transition of the machine works on ArUco markers (needs a camera's
/// ArucoMarkers to run).
bool uses_markers(const Machine& m);

}  // namespace cpm::fsm
