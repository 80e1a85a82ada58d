#include <cpm/rtdb/HistoryService.hpp>

#include <cpm/Logging.hpp>
#include <cpm/Timer.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/stamp_message.hpp>
#include <cpm/timer_ids.hpp>
#include <cpm/topics.hpp>

#include <HistoryStatus.h>
#include <cpm_topic_types.hpp>

#include "Ingest.hpp"
#include "Outlet.hpp"
#include "Save.hpp"
#include "RequestServer.hpp"

#include <fastrtps/xmlparser/XMLProfileManager.h>

#include <algorithm>
#include <condition_variable>
#include <filesystem>
#include <ctime>
#include <deque>
#include <map>
#include <set>
#include <mutex>
#include <thread>

// The service is four parts: the ingest (discovery, raw readers, the registry of objects) feeds
// the outlet (the store, then any further sinks); the request server answers from the store;
// the control thread here handles discovery, expires what is out of its window and publishes
// the status.

namespace cpm::rtdb {

namespace {

/// Fast DDS 2.9 delivers between participants of one process by direct calls. After the
/// process was stopped for longer than a lease (SIGSTOP, a debugger, a stalled VM) the reliable
/// path from the service's own writers (historyStatus, its log) to its recorder never delivers
/// again, while the same writers still reach other processes. Through the transports, as from
/// every other process, it recovers: the service pays one loopback hop for its own few samples
/// a second.
bool intraprocess_off()
{
    auto library = eprosima::fastrtps::xmlparser::XMLProfileManager::library_settings();
    library.intraprocess_delivery = eprosima::fastrtps::INTRAPROCESS_OFF;
    eprosima::fastrtps::xmlparser::XMLProfileManager::library_settings(library);
    return true;
}

/// The lease the service's participants announce: how long the others wait for them.
std::chrono::milliseconds own_lease(const ServiceOptions& options)
{
    return options.participant ? options.participant->lease : ParticipantOptions::from_init().lease;
}

}  // namespace

struct HistoryService::Impl
{
    ServiceOptions options;
    std::chrono::milliseconds lease = own_lease(options);  // what the others wait for it
    bool intraprocess_set = intraprocess_off();  // before any participant of the service is made
    // Saves in progress wait on these (declared before serving, whose stop() joins them).
    std::mutex saves_mutex;
    std::condition_variable saves_cv;
    bool saves_stopping = false;
    std::deque<TriggerSink::Fired> fired;  // --save-on matches waiting for the trigger thread
    std::set<size_t> triggers_saving;      // whose save runs: a trigger again meanwhile is in it already
    uint64_t triggers_ignored = 0;
    Store store;
    Outlet outlet;
    Ingest ingest;
    /// Requests, replies and status: through the default participant, or one of the service's
    /// own (options.participant, or made after a freeze, see heal_after_freeze).
    struct Serving
    {
        std::unique_ptr<Participant> own;
        RequestServer requests;
        Writer<HistoryStatus> status;

        Serving(const Store& store, std::unique_ptr<Participant> p, size_t workers, RequestServer::SaveHandler save)
            : own(std::move(p)), requests(store, participant(), workers, std::move(save)),
              status(participant(), topics::history_status.name, topics::history_status.writer)
        {
        }
        Participant& participant() const { return own ? *own : Participant::default_participant(); }
    };
    mutable std::mutex serving_mutex;  // counters() reads while the control thread replaces it
    std::unique_ptr<Serving> serving;
    uint64_t requests_before = 0, bad_requests_before = 0;  // counted by the servers replaced
    std::map<std::string, uint64_t> received_at_last_status;  // per topic, on the control thread
    std::thread control;
    std::thread trigger_thread;  // --save-on's saves
    std::unique_ptr<Participant> clock_participant;  // the clock's, with options.participant (else the default one)
    std::shared_ptr<Timer> clock;                    // options.clock_node's

    explicit Impl(ServiceOptions o)
        : options(std::move(o)), store(StoreOptions{{options.window_ns, options.max_bytes_per_topic}, options.max_bytes_total}),
          outlet(store, sinks_with_triggers()), ingest(options, outlet),
          serving(std::make_unique<Serving>(store, own_participant(false), options.workers, save_handler()))
    {
        for (const auto& [topic, window] : options.topic_windows_ns) store.set_retention(topic, {window, options.max_bytes_per_topic});
        control = std::thread([this] { control_loop(); });
        if (!options.save_on.empty()) trigger_thread = std::thread([this] { trigger_loop(); });
        if (!options.clock_node.empty()) follow_clock();
    }

    /// Joins the lab's simulated clock (ServiceOptions::clock_node): a tick returns once the
    /// recorder has every other node's announcement of a tick at or after it. A node that never
    /// announces (gone without a word) holds it back once, for kClockWait, and is named.
    void follow_clock()
    {
        constexpr auto kClockWait = std::chrono::seconds(5);  // within the lab clock's 10 s per step
        if (options.participant) clock_participant = std::make_unique<Participant>(*options.participant);
        Participant& p = clock_participant ? *clock_participant : Participant::default_participant();
        clock = Timer::create(p, options.clock_node, options.clock_period_ns,
                              std::min(timer_ids::kSimulatedCarOffset_ns, options.clock_period_ns / 2), TimerOptions{.simulated_time = true});
        clock->start_async([this, kClockWait](uint64_t t) {
            const auto behind = ingest.wait_for_clock(t, kClockWait);
            std::string names;
            for (const auto& n : behind) names += (names.empty() ? "'" : ", '") + n + "'";
            if (!behind.empty())
                CPM_LOG_ERROR("cpm_history: at %.3f s of lab time the recorder still lacks the announcement of the next tick "
                              "from %s after %lld s: the clock goes on without waiting for them (what they write may be lost to the recording)",
                              double(t) * 1e-9, names.c_str(), (long long)kClockWait.count());
        });
    }

    /// The options' sinks, and the watch for --save-on triggers when there are any.
    std::vector<std::shared_ptr<IngestSink>> sinks_with_triggers()
    {
        auto sinks = options.sinks;
        if (options.save_on.empty()) return sinks;
        sinks.push_back(std::make_shared<TriggerSink>(options.save_on, [this](const TriggerSink::Fired& f) {
            std::lock_guard lock(saves_mutex);
            if (!triggers_saving.insert(f.trigger).second) {
                ++triggers_ignored;
                return;
            }
            fired.push_back(f);
            saves_cv.notify_all();
        }));
        return sinks;
    }

    /// Saves the span around each trigger's sample, one after the other.
    void trigger_loop()
    {
        std::unique_lock lock(saves_mutex);
        for (;;) {
            saves_cv.wait(lock, [&] { return saves_stopping || !fired.empty(); });
            if (saves_stopping) return;
            const TriggerSink::Fired f = fired.front();
            fired.pop_front();
            lock.unlock();
            const SaveTrigger& t = options.save_on[f.trigger];
            const std::time_t secs = std::time_t(f.commit_ns / 1'000'000'000ull);
            std::tm utc{};
            gmtime_r(&secs, &utc);
            char when[40];
            std::strftime(when, sizeof when, "%Y%m%dT%H%M%S", &utc);
            std::string name = "save_" + std::string(when) + "." + std::to_string(f.commit_ns / 1'000'000 % 1000 + 1000).substr(1) + "Z_" +
                               t.topic + (f.key.empty() ? "" : "_" + f.key) + (options.save_format == "mcap" ? ".mcap" : ".db");
            std::replace_if(name.begin(), name.end(), [](char c) { return c == '/' || c == ' '; }, '_');
            const std::string dir = options.save_dir.empty() ? std::filesystem::current_path().string() : options.save_dir;
            // Around the trigger's data time (lab time in a simulated run, as its samples are).
            const SaveSpan span{.path = (std::filesystem::path(dir) / name).string(),
                                .from_ns = f.data_ns - std::min(f.data_ns, options.save_before_ns),
                                .to_ns = f.data_ns + options.save_after_ns,
                                .name = "save on " + t.text};
            CPM_LOG_INFO("cpm_history: %s triggered a save (%s): %s", t.topic.c_str(), t.text.c_str(), span.path.c_str());
            try {
                const SaveResult r = save_span(span, f.data_ns + (cpm::get_time_ns() - f.commit_ns));
                if (r.error.empty()) CPM_LOG_INFO("cpm_history: saved %s: %llu samples", r.path.c_str(), (unsigned long long)r.samples);
                else CPM_LOG_ERROR("cpm_history: the save %s: %s", r.path.c_str(), r.error.c_str());
            } catch (const std::exception& e) {
                CPM_LOG_ERROR("cpm_history: the save triggered by %s: %s", t.text.c_str(), e.what());
            }
            lock.lock();
            triggers_saving.erase(f.trigger);
        }
    }

    /// The options' participant; after a freeze one of the init settings when none is named.
    std::unique_ptr<Participant> own_participant(bool after_freeze) const
    {
        if (!options.participant && !after_freeze) return nullptr;
        ParticipantOptions srv = options.participant.value_or(ParticipantOptions::from_init());
        if (srv.name.empty()) srv.name = "cpm_history";
        return std::make_unique<Participant>(srv);
    }

    /// Requests answered and refused, the replaced servers' included.
    std::pair<uint64_t, uint64_t> request_counts() const
    {
        std::lock_guard lock(serving_mutex);
        return {requests_before + serving->requests.requests(), bad_requests_before + serving->requests.bad_requests()};
    }

    ~Impl()
    {
        if (clock) clock->stop();
        ingest.stop();  // a tick waiting for the clock's announcements returns
        clock.reset();
        {
            std::lock_guard lock(saves_mutex);
            saves_stopping = true;
        }
        saves_cv.notify_all();  // a save in progress closes its file with what it has
        if (trigger_thread.joinable()) trigger_thread.join();
        ingest.stop();
        control.join();
    }

    // ---- the dash-cam save -------------------------------------------------------------------
    /// Writes the span: what the store holds of it at once, then (as a sink of the ingest) what
    /// comes in until it has passed (`now` on the service's clock) and a moment more for samples
    /// stamped before its end. Throws cpm::Error when the file cannot be made.
    SaveResult save_span(const SaveSpan& span, uint64_t now)
    {
        auto saving = std::make_shared<Save>(span);
        ingest.locked([&] {
            saving->start(store);
            outlet.add_sink(saving);
        });
        {
            std::unique_lock lock(saves_mutex);
            const auto left = std::chrono::nanoseconds(span.to_ns > now ? span.to_ns - now : 0) + std::chrono::milliseconds(250);
            saves_cv.wait_for(lock, left, [&] { return saves_stopping; });
        }
        ingest.locked([&] { outlet.remove_sink(saving.get()); });
        return saving->finish();
    }

    /// "Now" on the clock the samples' data times are on: the wall clock, or in a simulated run
    /// (stamps on a lab clock from 0, far below the wall clock) the newest stamp held.
    uint64_t data_clock_now(const std::set<std::string>& topics) const
    {
        constexpr uint64_t kLabClockBelow = 1'000'000'000'000'000'000ull;  // 2001: no wall clock of a run
        uint64_t newest = 0;
        for (const auto& o : store.search({})) {
            if (o.kind != ObjectKind::instance || o.data_time != "create_stamp" || (!topics.empty() && !topics.count(o.topic))) continue;
            const auto last = store.latest(o.oid);
            if (last.ok()) newest = std::max(newest, last.sample.data_ns);
        }
        return newest > 0 && newest < kLabClockBelow ? newest : cpm::get_time_ns();
    }

    RequestServer::SaveHandler save_handler()
    {
        return [this](const HistoryRequest& rq) { return save(rq); };
    }

    /// A new recording of the span [now - t0, now + t1) by data time (the topics named, or all):
    /// the held samples at once, the live ones until the span has passed.
    HistoryReply save(const HistoryRequest& rq)
    {
        HistoryReply reply;
        reply.client_id(rq.client_id());
        reply.request_id(rq.request_id());
        auto refuse = [&](const std::string& why) {
            reply.status(std::string(history::to_string(history::Status::error)));
            reply.error("save: " + why);
            return reply;
        };
        const std::string dir = options.save_dir.empty() ? std::filesystem::current_path().string() : options.save_dir;
        const std::string& name = rq.file();
        if (name.empty() || name.find('/') != std::string::npos || name == "." || name == "..") {
            return refuse("file '" + name + "': give a file name; the service writes it into its save folder " + dir);
        }
        constexpr uint64_t kMaxAfter = 60'000'000'000ull;
        if (rq.t1() > kMaxAfter) return refuse("the span after now is at most 60 s, not " + std::to_string(rq.t1() / 1'000'000'000.0) + " s");
        SaveSpan span{.path = (std::filesystem::path(dir) / name).string(), .name = "save " + name};
        const auto held = store.search({});
        for (const auto& t : rq.objects()) {
            if (std::none_of(held.begin(), held.end(), [&](const ObjectInfo& o) { return o.topic == t; })) {
                return refuse("no topic '" + t + "' is held");
            }
            span.topics.insert(t);
        }
        const uint64_t now = data_clock_now(span.topics);
        span.from_ns = now - std::min(now, rq.t0());
        span.to_ns = now + rq.t1();
        SaveResult r;
        try {
            r = save_span(span, now);
        } catch (const std::exception& e) {
            return refuse(e.what());
        }
        reply.status(std::string(history::to_string(r.error.empty() ? history::Status::ok : history::Status::error)));
        reply.error(r.error);
        reply.file(r.path);
        reply.saved_samples(r.samples);
        reply.saved_objects(r.objects);
        reply.saved_from_ns(span.from_ns);
        reply.saved_to_ns(span.to_ns);
        return reply;
    }

    void control_loop()
    {
        uint64_t next_status = 0;
        StatusWatch watch;
        auto last_turn = std::chrono::steady_clock::now();
        while (ingest.process_events(std::chrono::milliseconds(100))) {
            const uint64_t now = cpm::get_time_ns();
            const auto turn = std::chrono::steady_clock::now();
            if (heal_after_freeze(turn - last_turn)) watch = {};
            last_turn = turn;
            ingest.locked([&] { store.expire(now); });
            if (now >= next_status) {
                publish_status(now);
                next_status = now + options.status_period_ns;
            }
            heal_one_sided_drop(now, watch);
        }
    }

    /// This loop turns every 100 ms. A turn that took nearly the lease means the process stood
    /// still (SIGSTOP, a debugger, a stalled VM) for long enough that the others dropped its
    /// participants while it may not have dropped them. Fast DDS 2.9 then never sends them its
    /// endpoints again (its writers of discovery data take the others for up to date): a client
    /// that waited through the freeze would never be answered again, while one started afresh is.
    /// New participants (new GUIDs) meet everyone afresh on both sides. The default participant
    /// (the process's log) cannot be replaced; the service serves from one of its own from then on.
    bool heal_after_freeze(std::chrono::steady_clock::duration turn)
    {
        if (turn < lease - std::min<std::chrono::milliseconds>(lease / 3, std::chrono::seconds(1))) return false;
        CPM_LOG_WARN("cpm_history: this process stood still for %.1f s (its lease: %.1f s): making the service's "
                     "participants anew, so that every other participant meets them afresh",
                     std::chrono::duration<double>(turn).count(), std::chrono::duration<double>(lease).count());
        ingest.rebuild();
        auto renewed = std::make_unique<Serving>(store, own_participant(true), options.workers, save_handler());
        serving->requests.stop();  // its counts are final from here
        std::lock_guard lock(serving_mutex);
        requests_before += serving->requests.requests();
        bad_requests_before += serving->requests.bad_requests();
        serving = std::move(renewed);
        return true;
    }

    /// After this process was stopped past the lease (SIGSTOP, a debugger, a stalled VM), the
    /// serving participant and the recorder may drop each other one-sidedly; Fast DDS 2.9 then
    /// never exchanges their endpoints again (Fast DDS issues #155 and #457), and the service's
    /// own status goes unrecorded. That was once seen as the status writer matching no reader;
    /// the writer's match count cannot show the drop the other way round (the writer still
    /// matching the recorder's reader that has dropped it), and a full test run failed with
    /// the status unrecorded all the same. The check is therefore on what arrives: no status
    /// recorded for 2 s and 3 periods gets the recorder replaced (a new participant meets
    /// everyone afresh). Another service's status on the domain counts as arriving too.
    struct StatusWatch
    {
        uint64_t received = 0, since = 0;
    };
    void heal_one_sided_drop(uint64_t now, StatusWatch& watch)
    {
        if (!ingest.records(topics::history_status.name)) return;
        const uint64_t received = ingest.received(topics::history_status.name);
        if (watch.since == 0 || received != watch.received) {
            watch = {received, now};
            return;
        }
        if (now - watch.since < std::max<uint64_t>(2'000'000'000ull, 3 * options.status_period_ns)) return;
        CPM_LOG_WARN("cpm_history: the recorder has received none of the service's own status for %llu ms "
                     "(a freeze past the lease?); replacing the recording participant",
                     (unsigned long long)((now - watch.since) / 1'000'000));
        ingest.rebuild();
        watch = {received, now};
    }

    void publish_status(uint64_t now)
    {
        HistoryStatus s;
        cpm::stamp_message(s, now, 0);
        s.service("cpm_history");
        const auto st = store.stats();
        s.objects(st.objects);
        s.alive(st.alive);
        s.samples(st.samples);
        s.bytes(st.bytes);
        s.evicted(st.evicted);
        s.dropped(ingest.dropped());
        s.lost(ingest.lost());
        const auto [answered, refused] = request_counts();
        s.requests(answered);
        s.bad_requests(refused);
        const double period_s = double(options.status_period_ns) * 1e-9;
        for (const auto& t : ingest.topic_counts()) {
            HistoryTopicStatus ts;
            ts.topic(t.topic);
            ts.type_name(t.type_name);
            ts.samples(t.received);
            ts.lost(t.lost);
            uint64_t& before = received_at_last_status[t.topic];
            ts.rate_hz(double(t.received - before) / period_s);
            before = t.received;
            s.topics().push_back(ts);
        }
        (void)serving->status.write(s);
    }
};

HistoryService::HistoryService(ServiceOptions options) : impl_(std::make_unique<Impl>(std::move(options))) {}

HistoryService::~HistoryService() = default;

const Store& HistoryService::store() const { return impl_->store; }

ServiceCounters HistoryService::counters() const
{
    const auto& d = *impl_;
    const auto [answered, refused] = d.request_counts();
    ServiceCounters c{d.ingest.topic_count(), d.ingest.received(), d.ingest.dropped(), answered, refused, d.ingest.lost(), {}};
    for (const auto& t : d.ingest.topic_counts()) {
        if (t.lost > 0) c.lost_by_topic[t.topic] = t.lost;
    }
    return c;
}

}  // namespace cpm::rtdb
