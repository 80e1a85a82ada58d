#include <cpm/hlc/Communicator.hpp>
#include <cpm/hlc/Middleware.hpp>

#include <cpm/AsyncReader.hpp>
#include <cpm/Error.hpp>
#include <cpm/LogThrottle.hpp>
#include <cpm/Logging.hpp>
#include <cpm/MultiVehicleReader.hpp>
#include <cpm/Timer.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/init.hpp>
#include <cpm/percentile.hpp>
#include <cpm/timer_ids.hpp>
#include <cpm/topics.hpp>
#include <cpm/vehicle/BridgeCore.hpp>

#include <ReadyStatus.h>
#include <SystemTrigger.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <thread>

namespace cpm::hlc {

namespace {

constexpr uint64_t kStopTrigger = UINT64_MAX;

uint64_t steady_now_ns()
{
    return uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch()).count());
}

}  // namespace

const char* to_string(Refusal reason)
{
    switch (reason) {
    case Refusal::not_assigned: return "not_assigned";
    case Refusal::future_stamp: return "future_stamp";
    case Refusal::past_period: return "past_period";
    case Refusal::bad_value: return "bad_value";
    }
    return "?";
}

// ---- MiddlewareCore ----------------------------------------------------------------------------

MiddlewareCore::MiddlewareCore(MiddlewareOptions options) : options_(std::move(options)) {}

VehicleStateList MiddlewareCore::begin_period(uint64_t t_now, const std::map<uint8_t, SampleResult<VehicleState>>& states,
                                              const std::map<uint8_t, SampleResult<VehicleObservation>>& observations, uint64_t steady_ns)
{
    VehicleStateList list;
    list.t_now(t_now);
    list.period_ms(options_.period_ns / 1'000'000);
    for (uint8_t id : options_.vehicle_ids) {
        list.active_vehicle_ids().push_back(id);
        if (auto s = states.find(id); s != states.end() && s->second.valid) list.state_list().push_back(s->second.sample);
        if (auto o = observations.find(id); o != observations.end() && o->second.valid) {
            list.vehicle_observation_list().push_back(o->second.sample);
        }
    }
    std::lock_guard<std::mutex> lock(mutex_);
    if (open_ && !answered_) ++unanswered_;
    open_ = true;
    answered_ = false;
    open_t_ = t_now;
    open_since_ = steady_ns;
    ++periods_;
    return list;
}

template <class Command>
Check MiddlewareCore::check_common(const Command& command, uint64_t now_ns, const std::string& value_problem)
{
    const unsigned id = command.vehicle_id();
    const uint64_t stamp = command.header().create_stamp().nanoseconds();
    std::lock_guard<std::mutex> lock(mutex_);
    Check c;
    auto refuse = [&](Refusal r, std::string why) {
        c.ok = false;
        c.reason = r;
        c.why = std::move(why);
    };
    if (std::find(options_.vehicle_ids.begin(), options_.vehicle_ids.end(), command.vehicle_id()) == options_.vehicle_ids.end()) {
        std::string ids;
        for (uint8_t v : options_.vehicle_ids) ids += (ids.empty() ? "" : ",") + std::to_string(v);
        refuse(Refusal::not_assigned, "vehicle " + std::to_string(id) + " is not assigned to this controller (it drives " + ids + ")");
    } else if (!value_problem.empty()) {
        refuse(Refusal::bad_value, "vehicle " + std::to_string(id) + ": " + value_problem);
    } else if (stamp > now_ns) {
        refuse(Refusal::future_stamp, "vehicle " + std::to_string(id) + ": create_stamp " + std::to_string(stamp) + " is " +
                                          std::to_string((stamp - now_ns) / 1000) + " us in the future");
    } else if (!open_) {
        refuse(Refusal::past_period, "vehicle " + std::to_string(id) + ": a command before the first period's list");
    } else if (stamp < open_t_) {
        refuse(Refusal::past_period, "vehicle " + std::to_string(id) + ": create_stamp " + std::to_string(stamp) +
                                         " answers a period already past (the newest list's t_now is " + std::to_string(open_t_) + ")");
    }
    if (c.ok) {
        ++forwarded_;
    } else {
        const auto k = size_t(c.reason);
        if (refused_[k]++ == 0) first_refusal_[k] = c.why;
    }
    return c;
}

Check MiddlewareCore::check(const VehicleCommandDirect& command, uint64_t now_ns)
{
    return check_common(command, now_ns, vehicle::command_problem(command, options_.calibration));
}
Check MiddlewareCore::check(const VehicleCommandSpeedCurvature& command, uint64_t now_ns)
{
    return check_common(command, now_ns, vehicle::command_problem(command, options_.calibration));
}
Check MiddlewareCore::check(const VehicleCommandTrajectory& command, uint64_t now_ns)
{
    return check_common(command, now_ns, vehicle::command_problem(command, options_.calibration));
}
Check MiddlewareCore::check(const VehicleCommandPathTracking& command, uint64_t now_ns)
{
    return check_common(command, now_ns, vehicle::command_problem(command, options_.calibration));
}

bool MiddlewareCore::answered(uint64_t t_now, uint64_t steady_ns)
{
    std::lock_guard<std::mutex> lock(mutex_);
    if (!open_ || answered_ || t_now != open_t_) {
        ++late_answers_;
        return false;
    }
    answered_ = true;
    ++answered_periods_;
    response_ms_.push_back(double(steady_ns - std::min(steady_ns, open_since_)) * 1e-6);
    return true;
}

bool MiddlewareCore::open_period_answered() const { return locked(answered_); }
uint64_t MiddlewareCore::open_period() const { return locked(open_t_); }
uint64_t MiddlewareCore::periods() const { return locked(periods_); }
uint64_t MiddlewareCore::answered_periods() const { return locked(answered_periods_); }
uint64_t MiddlewareCore::unanswered_periods() const { return locked(unanswered_); }
uint64_t MiddlewareCore::late_answers() const { return locked(late_answers_); }
uint64_t MiddlewareCore::forwarded() const { return locked(forwarded_); }
uint64_t MiddlewareCore::refused(Refusal reason) const { return locked(refused_[size_t(reason)]); }
uint64_t MiddlewareCore::refused() const
{
    std::lock_guard<std::mutex> lock(mutex_);
    uint64_t n = 0;
    for (uint64_t r : refused_) n += r;
    return n;
}
std::vector<double> MiddlewareCore::response_ms() const { return locked(response_ms_); }

std::string MiddlewareCore::stats_json() const
{
    std::lock_guard<std::mutex> lock(mutex_);
    nlohmann::ordered_json refused = nlohmann::ordered_json::object(), first = nlohmann::ordered_json::object();
    uint64_t total = 0;
    for (size_t k = 0; k < kRefusals; ++k) {
        refused[to_string(Refusal(k))] = refused_[k];
        total += refused_[k];
        if (refused_[k]) first[to_string(Refusal(k))] = first_refusal_[k];
    }
    std::vector<uint8_t> ids = options_.vehicle_ids;
    nlohmann::ordered_json j{{"controller", options_.name},
                             {"vehicles", std::vector<int>(ids.begin(), ids.end())},
                             {"period_ms", options_.period_ns / 1'000'000},
                             {"periods", periods_},
                             {"answered", answered_periods_},
                             {"unanswered", unanswered_ + (open_ && !answered_ ? 1 : 0)},
                             {"late_answers", late_answers_},
                             {"response_ms_p50", percentile(response_ms_, 0.5)},
                             {"response_ms_p99", percentile(response_ms_, 0.99)},
                             {"response_ms_max", percentile(response_ms_, 1.0)},
                             {"forwarded", forwarded_},
                             {"refused", total},
                             {"refused_by_reason", refused},
                             {"first_refusals", first}};
    return j.dump();
}

// ---- Middleware ---------------------------------------------------------------------------------

namespace {

ParticipantOptions controller_side(const MiddlewareOptions& o)
{
    ParticipantOptions p;  // this host only
    p.domain_id = o.controller_domain;
    p.name = "hlc_middleware_" + o.name;
    return p;
}

}  // namespace

struct Middleware::Impl
{
    MiddlewareOptions options;
    MiddlewareCore core;
    bool simulated = init_settings().simulated_time;
    Participant& lab = Participant::default_participant();
    Participant local;
    MultiVehicleReader<VehicleState> states{lab, topics::vehicle_state.name, options.vehicle_ids};
    MultiVehicleReader<VehicleObservation> observations{lab, topics::vehicle_observation.name, options.vehicle_ids};
    Writer<VehicleCommandDirect> direct_out{lab, topics::vehicle_command_direct.name, topics::vehicle_command_direct.writer};
    Writer<VehicleCommandSpeedCurvature> speed_out{lab, topics::vehicle_command_speed_curvature.name,
                                                   topics::vehicle_command_speed_curvature.writer};
    Writer<VehicleCommandTrajectory> trajectory_out{lab, topics::vehicle_command_trajectory.name, topics::vehicle_command_trajectory.writer};
    Writer<VehicleCommandPathTracking> path_out{lab, topics::vehicle_command_path_tracking.name, topics::vehicle_command_path_tracking.writer};
    Writer<VehicleStateList> lists{local, topics::vehicle_state_list.name, topics::vehicle_state_list.writer};
    Writer<SystemTrigger> triggers{local, topics::system_trigger.name, topics::system_trigger.writer};

    std::mutex mutex;
    std::condition_variable changed;
    bool announced = false;
    std::array<LogThrottle, kRefusals> refusal_log;  // each reason said at once, then once a second
    std::atomic<uint64_t> refused_writes{0};         // the command readers' threads count


    // Last: their callbacks use what is above.
    AsyncReader<ReadyStatus> answers{[this](std::vector<ReadyStatus>& s) { on_answers(s); }, local, topics::ready_status.name,
                                     in_arrival_order(topics::ready_status.reader)};
    AsyncReader<VehicleCommandDirect> direct_in{[this](std::vector<VehicleCommandDirect>& s) { relay(s, direct_out); }, local,
                                                topics::vehicle_command_direct.name, controller_reader()};
    AsyncReader<VehicleCommandSpeedCurvature> speed_in{[this](std::vector<VehicleCommandSpeedCurvature>& s) { relay(s, speed_out); }, local,
                                                       topics::vehicle_command_speed_curvature.name, controller_reader()};
    AsyncReader<VehicleCommandTrajectory> trajectory_in{[this](std::vector<VehicleCommandTrajectory>& s) { relay(s, trajectory_out); }, local,
                                                        topics::vehicle_command_trajectory.name, controller_reader()};
    AsyncReader<VehicleCommandPathTracking> path_in{[this](std::vector<VehicleCommandPathTracking>& s) { relay(s, path_out); }, local,
                                                    topics::vehicle_command_path_tracking.name, controller_reader()};

    explicit Impl(MiddlewareOptions o) : options(std::move(o)), core(options), local(controller_side(options)) {}

    /// The controller's answer to a period comes after its commands of that period, from one
    /// participant: DDS delivers them to this participant in that order on one receive thread.
    /// Handled on that thread, each command is checked and forwarded before the answer closes
    /// its period (on their readers' own threads an answer overtook a command under load, and
    /// the command was refused as answering a period already past).
    static ReaderOptions in_arrival_order(const ReaderOptions& r) { return r.on_dds_thread(); }
    /// Every command the controller writes (its writers are best effort by default: a reader
    /// that keeps all of them loses none to a burst of several cars' commands).
    static ReaderOptions controller_reader()
    {
        ReaderOptions r;
        r.keep_all = true;
        return in_arrival_order(r);
    }

    /// Lab time now: the open period's while the simulated clock waits for the answer.
    uint64_t lab_now() const { return simulated ? core.open_period() : get_time_ns(); }

    template <class Command>
    void relay(std::vector<Command>& commands, Writer<Command>& out)
    {
        for (const auto& c : commands) {
            const Check verdict = core.check(c, lab_now());
            if (verdict.ok) {
                if (!out.write(c)) ++refused_writes;
                continue;
            }
            uint64_t held = 0;
            std::lock_guard<std::mutex> lock(mutex);
            if (refusal_log[size_t(verdict.reason)].allow(get_time_ns(), held)) {
                CPM_LOG_WARN("hlc %s: refused a command (%s): %s (%llu refused in all)", options.name.c_str(), to_string(verdict.reason),
                             verdict.why.c_str(), (unsigned long long)core.refused());
            }
        }
    }

    void on_answers(std::vector<ReadyStatus>& answers_in)
    {
        for (const auto& a : answers_in) {
            if (a.source_id() != kReadySource) continue;
            const uint64_t t = a.next_start_stamp().nanoseconds();
            std::lock_guard<std::mutex> lock(mutex);
            if (t == UINT64_MAX) announced = true;
            else (void)core.answered(t, steady_now_ns());
            changed.notify_all();
        }
    }

    bool wait_for_controller(const std::function<bool()>& stop_requested)
    {
        const auto until = std::chrono::steady_clock::now() + options.controller_wait;
        std::unique_lock<std::mutex> lock(mutex);
        while (!announced && std::chrono::steady_clock::now() < until) {
            if (stop_requested()) return false;
            changed.wait_for(lock, std::chrono::milliseconds(50));
        }
        if (!announced) {
            CPM_LOG_ERROR("hlc %s: the controller did not announce itself within %lld ms (is it started with --dds_domain %d?); "
                          "running the periods without it",
                          options.name.c_str(), (long long)options.controller_wait.count(), options.controller_domain);
        }
        return true;
    }

    void period(uint64_t t_now, const std::function<bool()>& stop_requested)
    {
        const auto list = core.begin_period(t_now, states.get_samples(t_now), observations.get_samples(t_now), steady_now_ns());
        if (!lists.write(list)) CPM_LOG_WARN("hlc %s: DDS refused the list of t_now %llu", options.name.c_str(), (unsigned long long)t_now);
        if (!simulated) return;
        // The simulated clock waits while the controller computes.
        const auto until = std::chrono::steady_clock::now() + options.answer_timeout;
        std::unique_lock<std::mutex> lock(mutex);
        while (!core.open_period_answered() && std::chrono::steady_clock::now() < until && !stop_requested()) {
            changed.wait_for(lock, std::chrono::milliseconds(50));
        }
        if (!core.open_period_answered() && !stop_requested()) {
            CPM_LOG_WARN("hlc %s: no answer to the period at %llu within %lld ms; the clock goes on", options.name.c_str(),
                         (unsigned long long)t_now, (long long)options.answer_timeout.count());
        }
    }

    void relay_stop()
    {
        SystemTrigger stop;
        stop.next_start().nanoseconds(kStopTrigger);
        if (triggers.write(stop)) (void)triggers.wait_for_acknowledgments(std::chrono::milliseconds(1000));
    }
};

Middleware::Middleware(MiddlewareOptions options)
{
    if (options.vehicle_ids.empty()) throw cpm::Error("hlc_middleware: no vehicle ids (the cars the controller drives)");
    if (options.controller_domain < 0 || options.controller_domain > 232) {
        throw cpm::Error("hlc_middleware: the controller's domain " + std::to_string(options.controller_domain) + " is not in 0..232");
    }
    if (options.controller_domain == init_settings().domain_id) {
        throw cpm::Error("hlc_middleware: the controller's domain " + std::to_string(options.controller_domain) +
                         " is the lab's: it must be a domain of its own, or its commands would reach the cars unchecked");
    }
    if (options.period_ns == 0) throw cpm::Error("hlc_middleware: the period must be positive");
    impl_ = std::make_unique<Impl>(std::move(options));
}

Middleware::~Middleware() = default;

void Middleware::run(const std::function<bool()>& stop_requested)
{
    auto& d = *impl_;
    if (!d.wait_for_controller(stop_requested)) return;
    auto timer = Timer::create(d.lab, timer_ids::hlc_middleware(d.options.name), d.options.period_ns, 0,
                               TimerOptions{.wait_for_start = d.options.wait_for_start, .simulated_time_allowed = true});
    timer->run_until(stop_requested, [&](uint64_t t) { d.period(t, stop_requested); });
    d.relay_stop();
}

const MiddlewareCore& Middleware::core() const { return impl_->core; }

std::string Middleware::stats_json() const
{
    auto j = nlohmann::ordered_json::parse(impl_->core.stats_json());
    j["refused_writes"] = impl_->refused_writes.load();
    return j.dump();
}

}  // namespace cpm::hlc
