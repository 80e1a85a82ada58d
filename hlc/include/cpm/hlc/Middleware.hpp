#pragma once
// cpm::hlc — the middleware between a user's controller and the lab (cpm_lab's per-computer
// middleware). Every period of the lab clock it builds the controller's VehicleStateList from
// the lab's newest valid states and observations of its cars and writes it on the controller's
// own domain; it forwards the controller's commands to the lab, each checked first; it relays
// the lab's stop. On the simulated clock a period waits (up to answer_timeout of real time) until
// the controller answered it, so a controller holds the clock as long as it computes.
//
// A command is refused (not forwarded, counted, logged with its reason) when it is for a car
// not assigned to this controller, stamped in the future, stamped before the newest list's
// t_now (it answers a period already past), or has a value the car's bridge would refuse (NaN,
// infinities, beyond the bridge's limits). Each period's response time (list written → the
// controller's answer) is measured.
#include <cpm/SampleResult.hpp>
#include <cpm/vehicle/Calibration.hpp>

#include <VehicleCommandDirect.h>
#include <VehicleCommandPathTracking.h>
#include <VehicleCommandSpeedCurvature.h>
#include <VehicleCommandTrajectory.h>
#include <VehicleObservation.h>
#include <VehicleState.h>
#include <VehicleStateList.h>

#include <array>
#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace cpm::hlc {

enum class Refusal { not_assigned, future_stamp, past_period, bad_value };
inline constexpr size_t kRefusals = 4;
/// "not_assigned", "future_stamp", "past_period", "bad_value".
const char* to_string(Refusal reason);

struct MiddlewareOptions
{
    std::string name = "hlc";          ///< the controller's name: in logs and the timer's id
    std::vector<uint8_t> vehicle_ids;  ///< the cars the controller drives
    uint64_t period_ns = 100'000'000;  ///< the controller's period
    int controller_domain = -1;        ///< the domain the controller and the middleware share
    vehicle::Calibration calibration;  ///< the bridge's limits a command is checked against
    /// On the simulated clock: how long (real time) a period waits for the controller's answer
    /// before the clock goes on without it.
    std::chrono::milliseconds answer_timeout{10'000};
    /// How long the start waits for the controller to announce itself.
    std::chrono::milliseconds controller_wait{30'000};
    bool wait_for_start = true;        ///< the timer waits for the lab's start
};

/// A verdict on one command.
struct Check
{
    bool ok = true;
    Refusal reason = Refusal::not_assigned;
    std::string why;  ///< names the car, the stamp or the field and value
};

/// The middleware's bookkeeping without DDS: the open period, the checks, the response times.
/// Thread-safe (the timer's thread opens periods, the readers' threads check and answer).
class MiddlewareCore
{
public:
    explicit MiddlewareCore(MiddlewareOptions options);

    /// Opens the period at t_now (a period still unanswered is counted so) and returns its list:
    /// each assigned car's sample that is valid at t_now. `steady_ns`: a monotonic clock's now.
    VehicleStateList begin_period(uint64_t t_now, const std::map<uint8_t, SampleResult<VehicleState>>& states,
                                  const std::map<uint8_t, SampleResult<VehicleObservation>>& observations, uint64_t steady_ns);
    /// Whether the command may go to the lab at lab time now_ns; a refusal is counted.
    Check check(const VehicleCommandDirect& command, uint64_t now_ns);
    Check check(const VehicleCommandSpeedCurvature& command, uint64_t now_ns);
    Check check(const VehicleCommandTrajectory& command, uint64_t now_ns);
    Check check(const VehicleCommandPathTracking& command, uint64_t now_ns);
    /// The controller answered the period at t_now; true when that is the open period and it was
    /// not answered yet (its response time is then recorded).
    bool answered(uint64_t t_now, uint64_t steady_ns);
    /// Whether the open period is answered (true before the first).
    bool open_period_answered() const;
    /// The open period's t_now (0 before the first).
    uint64_t open_period() const;

    uint64_t periods() const;
    uint64_t answered_periods() const;
    uint64_t unanswered_periods() const;  ///< closed without an answer
    uint64_t late_answers() const;        ///< answers to a period already closed
    uint64_t forwarded() const;
    uint64_t refused(Refusal reason) const;
    uint64_t refused() const;
    /// The response times so far, ms.
    std::vector<double> response_ms() const;
    /// The counts, the response times' p50/p99/max and the first refusal of each kind, as JSON.
    std::string stats_json() const;

private:
    /// A copy of a member, read under the lock.
    template <class T>
    T locked(const T& member) const
    {
        std::lock_guard<std::mutex> lock(mutex_);
        return member;
    }
    template <class Command>
    Check check_common(const Command& command, uint64_t now_ns, const std::string& value_problem);

    MiddlewareOptions options_;
    mutable std::mutex mutex_;
    uint64_t open_t_ = 0;
    uint64_t open_since_ = 0;
    bool open_ = false, answered_ = true;
    uint64_t periods_ = 0, answered_periods_ = 0, unanswered_ = 0, late_answers_ = 0, forwarded_ = 0;
    std::array<uint64_t, kRefusals> refused_{};
    std::array<std::string, kRefusals> first_refusal_;
    std::vector<double> response_ms_;
};

/// The middleware as a node: the lab's participant is the process's (cpm::init's), the
/// controller's domain one of its own (this host only).
class Middleware
{
public:
    /// Throws cpm::Error for options that cannot work (no cars, no controller domain, the same
    /// domain as the lab's).
    explicit Middleware(MiddlewareOptions options);
    ~Middleware();
    /// Waits for the controller, then runs the periods until stop_requested or the lab stops the
    /// timers; relays the stop to the controller.
    void run(const std::function<bool()>& stop_requested);
    const MiddlewareCore& core() const;
    std::string stats_json() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm::hlc
