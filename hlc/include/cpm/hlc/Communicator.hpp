#pragma once
// cpm::hlc — a user's high-level controller (HLC), as cpm_lab's HLCCommunicator: every period
// the lab hands it one list of its cars' states, it answers with commands before the period
// ends.
//
//   cpm::init(argc, argv);                          // --dds_domain: the controller's own domain
//   cpm::hlc::Communicator hlc({1, 2, 3, 4});
//   cpm::Writer<VehicleCommandTrajectory> out(cpm::topics::vehicle_command_trajectory.name);
//   hlc.on_each_timestep([&](const VehicleStateList& list) { ...; (void)out.write(command); });
//   hlc.start();                                    // until the lab stops, stop() or Ctrl-C
//
// The controller runs on a DDS domain of its own, shared only with its hlc_middleware (`cpm lab
// run` gives it --dds_domain of it): its plain writers of the command topics reach the
// middleware, which checks every command and forwards it to the lab. Stamp each command with the
// list's t_now (cpm::stamp_message(command, list.t_now(), …)): the middleware refuses one stamped
// before the newest list's t_now (it answers a period already past) or in the future.
//
// A step whose callback still runs when the next list arrives is cancelled: on_cancel_timestep
// is called (on the communicator's receiving thread, while the step goes on: set a flag the
// step reads to give up), the step is counted and the new list is not run (never queued);
// cancellations are logged at most once a second with their count. A callback that throws is
// logged with its message, counted as failed, and the controller goes on with the next list.
#include <cpm/Participant.hpp>

#include <VehicleStateList.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

namespace cpm::hlc {

/// The ReadyStatus source id a controller answers with on its own domain.
inline constexpr const char* kReadySource = "hlc";

struct CommunicatorOptions
{
    /// The participant on the controller's domain; nullptr: the process's (cpm::init's).
    Participant* participant = nullptr;
    /// Asked every 50 ms while start() waits: true ends it. Empty: SIGINT/SIGTERM end it
    /// (start() calls cpm::cli::stop_on_signals()).
    std::function<bool()> stop_requested;
};

class Communicator
{
public:
    using StepCallback = std::function<void(const VehicleStateList&)>;

    /// A controller of these cars; throws cpm::Error for an empty list or id 0.
    explicit Communicator(std::vector<uint8_t> vehicle_ids, CommunicatorOptions options = {});
    ~Communicator();
    Communicator(const Communicator&) = delete;
    Communicator& operator=(const Communicator&) = delete;

    /// Called once with the first list, before on_each_timestep of that list.
    void on_first_timestep(StepCallback callback);
    /// Called with every list (on the communicator's step thread, one at a time).
    void on_each_timestep(StepCallback callback);
    /// Called when the next list arrives while a step still runs (see above).
    void on_cancel_timestep(std::function<void()> callback);
    /// Called once when the controller stops: the lab stopped it, stop() or a signal.
    void on_stop(std::function<void()> callback);

    /// Announces the controller to its middleware and runs the steps until the lab stops it,
    /// stop() or stop_requested; then calls on_stop and returns. Throws cpm::Error when called
    /// twice or without on_each_timestep.
    void start();
    /// Ends start() from any thread (a callback too); returns at once.
    void stop();

    const std::vector<uint8_t>& vehicle_ids() const;
    uint64_t steps() const;            ///< lists whose on_each_timestep returned
    uint64_t cancelled_steps() const;  ///< steps cancelled by the next list
    uint64_t failed_steps() const;     ///< callbacks that threw

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm::hlc
