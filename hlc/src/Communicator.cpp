#include <cpm/hlc/Communicator.hpp>

#include <cpm/AsyncReader.hpp>
#include <cpm/CommandLine.hpp>
#include <cpm/Error.hpp>
#include <cpm/LogThrottle.hpp>
#include <cpm/Logging.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/topics.hpp>

#include <ReadyStatus.h>
#include <SystemTrigger.h>

#include <atomic>
#include <condition_variable>
#include <mutex>
#include <optional>
#include <thread>

namespace cpm::hlc {

namespace {
/// The announcement's stamp: "here, not yet an answer" (a step's answer carries its t_now, which
/// may be 0 on the simulated clock).
constexpr uint64_t kAnnounce = UINT64_MAX;
constexpr uint64_t kStop = UINT64_MAX;  // a SystemTrigger that stops every timer
}  // namespace

struct Communicator::Impl
{
    std::vector<uint8_t> vehicle_ids;
    CommunicatorOptions options;
    Participant& participant;
    StepCallback first, each;
    std::function<void()> cancel, stopped;

    std::mutex mutex;
    std::condition_variable wake;
    std::optional<VehicleStateList> pending;  // the list the step thread is to run
    bool running = false;                     // a step runs (or is about to)
    bool stopping = false, started = false, had_first = false;
    std::atomic<uint64_t> steps{0}, cancelled{0}, failed{0};
    LogThrottle cancel_log;
    std::thread step_thread;

    Writer<ReadyStatus> ready;
    // Last: their callbacks use what is above, and they go first.
    std::unique_ptr<AsyncReader<VehicleStateList>> lists;
    std::unique_ptr<AsyncReader<SystemTrigger>> triggers;

    Impl(std::vector<uint8_t> ids, CommunicatorOptions o)
        : vehicle_ids(std::move(ids)),
          options(std::move(o)),
          participant(options.participant ? *options.participant : Participant::default_participant()),
          ready(participant, topics::ready_status.name, topics::ready_status.writer)
    {
    }

    void answer(uint64_t stamp)
    {
        ReadyStatus r;
        r.source_id(kReadySource);
        r.next_start_stamp().nanoseconds(stamp);
        if (!ready.write(r)) CPM_LOG_WARN("hlc: DDS refused the controller's ready status");
    }

    void on_list(std::vector<VehicleStateList>& samples)
    {
        for (auto& list : samples) {
            std::unique_lock<std::mutex> lock(mutex);
            if (stopping) return;
            if (running) {
                ++cancelled;
                uint64_t held = 0;
                const bool say = cancel_log.allow(get_time_ns(), held);
                lock.unlock();
                if (say) {
                    CPM_LOG_WARN("hlc: the step was still running when the list of t_now %llu came: cancelled (%llu cancelled in all)",
                                 (unsigned long long)list.t_now(), (unsigned long long)cancelled.load());
                }
                if (cancel) cancel();
                continue;
            }
            running = true;
            pending = std::move(list);
            wake.notify_all();
        }
    }

    void on_trigger(std::vector<SystemTrigger>& samples)
    {
        for (const auto& t : samples) {
            if (t.next_start().nanoseconds() == kStop) request_stop();
        }
    }

    void request_stop()
    {
        std::lock_guard<std::mutex> lock(mutex);
        stopping = true;
        wake.notify_all();
    }

    /// Runs the callbacks of one list; false when one threw (said in the log).
    bool run_step(const VehicleStateList& list)
    {
        try {
            if (!had_first) {
                had_first = true;
                if (first) first(list);
            }
            each(list);
            return true;
        } catch (const std::exception& e) {
            CPM_LOG_ERROR("hlc: the step of t_now %llu failed: %s (%llu failed in all); going on", (unsigned long long)list.t_now(),
                          e.what(), (unsigned long long)failed.load() + 1);
        } catch (...) {
            CPM_LOG_ERROR("hlc: the step of t_now %llu failed with an exception that is not a std::exception; going on",
                          (unsigned long long)list.t_now());
        }
        return false;
    }

    void step_loop()
    {
        std::unique_lock<std::mutex> lock(mutex);
        for (;;) {
            wake.wait(lock, [&] { return stopping || pending.has_value(); });
            if (stopping) return;
            VehicleStateList list = std::move(*pending);
            pending.reset();
            lock.unlock();
            const bool ok = run_step(list);
            lock.lock();
            running = false;  // before the answer: a list that comes after it starts a step
            lock.unlock();
            if (ok) {
                ++steps;
                answer(list.t_now());
            } else {
                ++failed;
            }
            lock.lock();
        }
    }
};

Communicator::Communicator(std::vector<uint8_t> vehicle_ids, CommunicatorOptions options)
{
    if (vehicle_ids.empty()) throw cpm::Error("hlc::Communicator: no vehicle ids (give the cars the controller drives)");
    for (uint8_t id : vehicle_ids) {
        if (id == 0) throw cpm::Error("hlc::Communicator: vehicle id 0 is not a car (ids are 1..255)");
    }
    impl_ = std::make_unique<Impl>(std::move(vehicle_ids), std::move(options));
}

Communicator::~Communicator()
{
    stop();
    impl_->lists.reset();
    impl_->triggers.reset();
    if (impl_->step_thread.joinable()) impl_->step_thread.join();
}

void Communicator::on_first_timestep(StepCallback callback) { impl_->first = std::move(callback); }
void Communicator::on_each_timestep(StepCallback callback) { impl_->each = std::move(callback); }
void Communicator::on_cancel_timestep(std::function<void()> callback) { impl_->cancel = std::move(callback); }
void Communicator::on_stop(std::function<void()> callback) { impl_->stopped = std::move(callback); }

void Communicator::start()
{
    auto& d = *impl_;
    {
        std::lock_guard<std::mutex> lock(d.mutex);
        if (d.started) throw cpm::Error("hlc::Communicator: start() called twice");
        if (!d.each) throw cpm::Error("hlc::Communicator: start() without on_each_timestep (what would the controller do?)");
        d.started = true;
    }
    std::function<bool()> stop_requested = d.options.stop_requested;
    if (!stop_requested) {
        cli::stop_on_signals();
        stop_requested = cli::stop_requested;
    }
    d.step_thread = std::thread([&d] { d.step_loop(); });
    d.triggers = std::make_unique<AsyncReader<SystemTrigger>>([&d](std::vector<SystemTrigger>& s) { d.on_trigger(s); }, d.participant,
                                                               topics::system_trigger.name, topics::system_trigger.reader);
    d.lists = std::make_unique<AsyncReader<VehicleStateList>>([&d](std::vector<VehicleStateList>& s) { d.on_list(s); }, d.participant,
                                                               topics::vehicle_state_list.name, topics::vehicle_state_list.reader);
    d.answer(kAnnounce);
    {
        std::unique_lock<std::mutex> lock(d.mutex);
        while (!d.stopping) {
            lock.unlock();
            const bool asked = stop_requested();
            lock.lock();
            if (asked) d.stopping = true;
            else d.wake.wait_for(lock, std::chrono::milliseconds(50), [&] { return d.stopping; });
        }
        d.wake.notify_all();
    }
    d.lists.reset();
    d.triggers.reset();
    d.step_thread.join();  // a step that runs is let finish
    if (d.cancelled) CPM_LOG_INFO("hlc: %llu step(s) cancelled in all", (unsigned long long)d.cancelled.load());
    if (d.stopped) d.stopped();
}

void Communicator::stop() { impl_->request_stop(); }

const std::vector<uint8_t>& Communicator::vehicle_ids() const { return impl_->vehicle_ids; }
uint64_t Communicator::steps() const { return impl_->steps; }
uint64_t Communicator::cancelled_steps() const { return impl_->cancelled; }
uint64_t Communicator::failed_steps() const { return impl_->failed; }

}  // namespace cpm::hlc
