#include "Ingest.hpp"

#include <cpm/Error.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/Logging.hpp>
#include <cpm/rtdb/IdlDecoder.hpp>
#include <cpm/topics.hpp>

#include "RawType.hpp"

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/Topic.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <map>
#include <optional>
#include <set>

namespace cpm::rtdb {

namespace dds = eprosima::fastdds::dds;

namespace {

/// The instance key as cpm prints it when the IDL does not describe the type: a lab type's
/// vehicle id (the one-byte key the handle starts with), otherwise the handle in hex; "" for an
/// unkeyed topic.
std::string key_text(const rtps::InstanceHandle_t& h, bool keyed)
{
    if (!keyed) return "";
    bool small = true;
    for (size_t i = 1; i < 16; ++i) small = small && h.value[i] == 0;
    if (small) return std::to_string(unsigned(h.value[0]));
    static const char* hex = "0123456789abcdef";
    std::string out;
    for (size_t i = 0; i < 16; ++i) {
        out += hex[h.value[i] >> 4];
        out += hex[h.value[i] & 15];
    }
    return out;
}

/// Something discovery told us, handled on the service's own thread (creating readers inside
/// a discovery callback can deadlock Fast DDS).
struct Event
{
    enum Kind { writer_found, writer_gone, process_found, process_gone } kind;
    RawEndpoint writer;  ///< writer_found, writer_gone
    std::string name;    ///< process_found: the participant's name
    rtps::GUID_t guid;
};

std::vector<std::regex> compile(const std::vector<std::string>& patterns, const char* flag)
{
    std::vector<std::regex> out;
    for (const auto& p : patterns) {
        try {
            out.emplace_back(p);
        } catch (const std::regex_error& e) {
            throw Error(std::string(flag) + " '" + p + "' is not a regular expression: " + e.what());
        }
    }
    return out;
}

/// Samples too short to hold a header: the first ten are logged, outside the lock.
struct Skipped
{
    size_t count = 0, size = 0;
};

}  // namespace

struct Ingest::Impl
{
    /// One recorded topic: a raw reader on the recording participant.
    struct TopicRec : public dds::DataReaderListener
    {
        Impl* ingest = nullptr;
        std::string name, type_name;
        bool keyed = false;
        const IdlDecoder* types = nullptr;  ///< the lab's IDL when it describes the type: keys and stamps exact
        bool recorded = true;               ///< false: read only for the clock's announcements (excluded from the recording)
        bool announces_ticks = false;       ///< the clock's readyStatus, with a clock to follow
        std::optional<bool> has_header;     ///< decided from the IDL, else from the first sample
        dds::Topic* topic = nullptr;
        dds::DataReader* reader = nullptr;
        uint64_t received = 0, lost = 0;
        std::map<rtps::GUID_t, uint64_t> last_sequence;  ///< per writer: the newest sequence number taken
        void on_data_available(dds::DataReader* r) override { ingest->ingest(*this, r); }
    };

    /// What a topic's reader had counted when its recorder was replaced (rebuild()).
    struct Carried
    {
        uint64_t received = 0, lost = 0;
        std::map<rtps::GUID_t, uint64_t> last_sequence;
    };

    Ingest& self;
    Outlet& out;
    Registry registry;
    std::vector<std::regex> include, exclude;
    ParticipantOptions recorder_options;
    std::unique_ptr<Participant> recorder;
    dds::Subscriber* raw_subscriber = nullptr;
    std::map<std::string, std::unique_ptr<TopicRec>> topics;  // under self.mutex_
    std::map<std::string, Carried> carried;                   // under self.mutex_

    std::mutex events_mutex;
    std::condition_variable events_cv;
    std::deque<Event> events;
    bool stopping = false;

    /// The lab's simulated clock as the recording participant sees it (ServiceOptions::clock_node):
    /// every node's newest announced tick, from the readyStatus samples this participant took.
    struct ClockWatch
    {
        std::string self;  ///< the service's own node: not waited for ("" when it follows no clock)
        std::mutex mutex;
        std::condition_variable changed;
        std::map<std::string, uint64_t> announced;
        std::set<std::string> given_up;  ///< waited for in vain: not again until it announces anew
        bool stopping = false;
    } clock;

    Impl(Ingest& i, const ServiceOptions& options, Outlet& o)
        : self(i), out(o), registry(o), include(compile(options.include, "--include")), exclude(compile(options.exclude, "--exclude"))
    {
        recorder_options = options.participant.value_or(ParticipantOptions::from_init());
        recorder_options.name = recorder_name(recorder_options.name);
        recorder_options.on_discovery = [this](const DiscoveryEvent& e) { on_discovery(e); };
        clock.self = options.clock_node;
        open();
    }

    ~Impl()
    {
        close_readers(topics);
        close();
    }

    void open()
    {
        recorder = std::make_unique<Participant>(recorder_options);
        raw_subscriber = recorder->native()->create_subscriber(dds::SUBSCRIBER_QOS_DEFAULT);
        if (!raw_subscriber) throw Error("cpm_history: cannot create the recording subscriber");
    }

    /// Deletes the readers while their listeners (the TopicRecs) still exist.
    void close_readers(std::map<std::string, std::unique_ptr<TopicRec>>& recs)
    {
        for (auto& [name, t] : recs) {
            if (t->reader) {
                t->reader->set_listener(nullptr);
                raw_subscriber->delete_datareader(t->reader);
                t->reader = nullptr;
            }
            if (t->topic) recorder->native()->delete_topic(t->topic);
            t->topic = nullptr;
        }
    }

    void close()
    {
        recorder->native()->delete_subscriber(raw_subscriber);
        recorder->native()->set_listener(nullptr);
        recorder.reset();
    }

    /// A new recording participant in place of the old one: every other participant meets it
    /// as new, so discovery runs afresh on both sides. Each topic is subscribed again as its
    /// writers are found; what its readers counted carries over, and samples of a writer that
    /// were taken before (a transient-local writer's history, sent again to the new reader) are
    /// skipped by their sequence numbers.
    void rebuild()
    {
        std::map<std::string, std::unique_ptr<TopicRec>> old;
        self.locked([&] { old.swap(topics); });
        close_readers(old);
        self.locked([&] {
            for (auto& [name, t] : old) carried[name] = {t->received, t->lost, std::move(t->last_sequence)};
        });
        close();
        open();
    }

    // ---- discovery -------------------------------------------------------------------------
    void push(Event e)
    {
        std::lock_guard lock(events_mutex);
        events.push_back(std::move(e));
        events_cv.notify_one();
    }

    void on_discovery(const DiscoveryEvent& d)
    {
        Event e{};
        e.guid = fast_dds_guid(d);
        switch (d.kind) {
        case DiscoveryEvent::Kind::participant_found: e.kind = Event::process_found; break;
        case DiscoveryEvent::Kind::participant_gone: e.kind = Event::process_gone; break;
        case DiscoveryEvent::Kind::writer_found: e.kind = Event::writer_found; break;
        case DiscoveryEvent::Kind::writer_gone: e.kind = Event::writer_gone; break;
        default: return;
        }
        e.name = d.participant_name;
        e.writer = raw_endpoint(d);
        push(std::move(e));
    }

    /// readyStatus, read for the clock's announcements when the service follows a clock.
    bool clock_topic(const std::string& topic) const { return !clock.self.empty() && topic == topics::ready_status.name; }

    bool wanted(const std::string& topic) const
    {
        if (topics::is_history_control(topic)) return false;
        for (const auto& re : exclude) {
            if (std::regex_match(topic, re)) return false;
        }
        if (include.empty()) return true;
        for (const auto& re : include) {
            if (std::regex_match(topic, re)) return true;
        }
        return false;
    }

    void handle(const Event& e, uint64_t now)
    {
        switch (e.kind) {
        case Event::process_found: return registry.process_found(e.guid.guidPrefix, e.name, now);
        case Event::process_gone: return registry.process_gone(e.guid.guidPrefix, now);
        case Event::writer_gone: return registry.writer_gone(e.writer.topic, e.guid, now);
        case Event::writer_found: return;  // subscribe(), outside the lock
        }
    }

    void subscribe(const RawEndpoint& e)
    {
        auto rec = std::make_unique<TopicRec>();
        rec->ingest = this;
        rec->name = e.topic;
        rec->type_name = e.type_name;
        rec->keyed = e.keyed;
        rec->recorded = wanted(e.topic);
        rec->announces_ticks = clock_topic(e.topic);
        const IdlDecoder* types = IdlDecoder::lab_types();
        if (types && types->knows(e.type_name)) {
            rec->types = types;
            rec->has_header = types->has_header(e.type_name);
        }
        auto* participant = recorder->native();
        if (!register_raw_type(participant, e, types)) {
            CPM_LOG_ERROR("cpm_history: cannot register type '%s' of topic '%s'; not recorded", e.type_name.c_str(), e.topic.c_str());
            return;
        }
        rec->topic = participant->create_topic(e.topic, e.type_name, dds::TOPIC_QOS_DEFAULT);
        if (!rec->topic) {
            CPM_LOG_ERROR("cpm_history: cannot create topic '%s' (type '%s'); not recorded", e.topic.c_str(), e.type_name.c_str());
            return;
        }
        // Compatible with the first writer seen: as reliable and as durable as it offers.
        const dds::DataReaderQos qos = raw_reader_qos(e.reliable, e.transient_local);
        rec->reader = raw_subscriber->create_datareader(rec->topic, qos, rec.get(), dds::StatusMask::data_available());
        if (!rec->reader) {
            CPM_LOG_ERROR("cpm_history: cannot create a reader for topic '%s'; not recorded", e.topic.c_str());
            participant->delete_topic(rec->topic);
            return;
        }
        if (rec->recorded) CPM_LOG_INFO("cpm_history: recording topic '%s' (type '%s'%s)", e.topic.c_str(), e.type_name.c_str(), e.keyed ? ", keyed" : "");
        std::lock_guard lock(self.mutex_);
        if (auto c = carried.find(e.topic); c != carried.end()) {
            rec->received = c->second.received;
            rec->lost = c->second.lost;
            rec->last_sequence = std::move(c->second.last_sequence);
            carried.erase(c);
        }
        topics[e.topic] = std::move(rec);
    }

    // ---- samples ---------------------------------------------------------------------------
    void ingest(TopicRec& t, dds::DataReader* reader)
    {
        Skipped skipped;
        {
            std::lock_guard lock(self.mutex_);
            take_all(t, reader, skipped);
        }
        // Logged outside the lock: the log topic is recorded too, and Fast DDS may deliver a
        // write to a reader in this process on the writing thread, which would take the lock again.
        for (size_t i = 0; i < skipped.count; ++i) {
            CPM_LOG_WARN("cpm_history: topic '%s': a sample of %zu bytes is too short to hold a Header (4 + 16 bytes); skipped",
                         t.name.c_str(), skipped.size);
        }
    }

    /// The samples its writer sent before this one that never arrived: a writer numbers
    /// everything it sends, so a jump means a best-effort sample dropped or a reliable writer's
    /// history overwritten while the service could not keep up. nullopt for a sample taken
    /// before (sent again to a reader made anew).
    std::optional<uint64_t> lost_before(TopicRec& t, const rtps::GUID_t& writer, uint64_t seq)
    {
        auto [last, first] = t.last_sequence.try_emplace(writer, seq);
        if (first) return 0;
        if (seq <= last->second) return std::nullopt;
        const uint64_t lost = seq - last->second - 1;
        last->second = seq;
        return lost;
    }

    /// A node's announcement of its next tick on the lab's simulated clock. This participant's
    /// receive thread delivers what a node wrote in the order it wrote it, so once its
    /// announcement is here, all it wrote before (in the tick that ended with it) is here too.
    void note_announcement(const TopicRec& t, const std::vector<uint8_t>& bytes)
    {
        const auto ready = t.types ? t.types->decode(t.type_name, bytes) : std::nullopt;
        if (!ready) return;
        const std::string node = ready->value("source_id", "");
        const uint64_t next = ready->value(nlohmann::json::json_pointer("/next_start_stamp/nanoseconds"), uint64_t(0));
        if (node.empty() || node == clock.self) return;
        {
            std::lock_guard lock(clock.mutex);
            uint64_t& newest = clock.announced[node];
            newest = std::max(newest, next);  // an older announcement may come after a newer one
            clock.given_up.erase(node);
        }
        clock.changed.notify_all();
    }

    /// Takes every sample the reader holds to the outlet; under the lock.
    void take_all(TopicRec& t, dds::DataReader* reader, Skipped& skipped)
    {
        RawSample raw;
        dds::SampleInfo info;
        while (reader->take_next_sample(&raw, &info) == ReturnCode_t::RETCODE_OK) {
            const uint64_t now = cpm::get_time_ns();
            rtps::GUID_t writer;
            rtps::iHandle2GUID(writer, info.publication_handle);
            const auto gap = lost_before(t, writer, info.sample_identity.sequence_number().to64long());
            if (!gap) continue;  // taken before
            const uint64_t lost = t.recorded ? *gap : 0;
            t.lost += lost;
            self.lost_ += lost;
            if (!info.valid_data) {
                if (info.instance_state != dds::ALIVE_INSTANCE_STATE) registry.instance_ended(t.name, info.instance_handle, now);
                continue;
            }
            if (t.announces_ticks) note_announcement(t, raw.bytes);
            if (!t.recorded) continue;
            ++t.received;
            ++self.received_;
            const auto& b = raw.bytes;
            // Encapsulation + Header; a type whose IDL has no Header (SystemTrigger) only needs
            // its encapsulation.
            if (b.size() < (t.has_header.value_or(true) ? 4 + 16 : 4)) {
                if (++self.dropped_ <= 10) {
                    ++skipped.count;
                    skipped.size = b.size();
                }
                continue;
            }
            const bool little = b[1] & 1;  // CDR_LE / PL_CDR_LE
            auto u64 = [&](size_t at) {
                uint64_t v = 0;
                for (size_t i = 0; i < 8; ++i) v |= uint64_t(b[at + (little ? i : 7 - i)]) << (8 * i);
                return v;
            };
            const uint64_t source = source_time_ns(info);
            // A type the IDL does not describe is taken to begin with a Header when its first
            // sample's stamps look like one (valid after created, by less than an hour, and not
            // from the future); a Log's string or a Parameter's name do not.
            if (!t.has_header) {
                const uint64_t create = u64(4), valid_after = u64(12);
                t.has_header = create <= now + 3'600'000'000'000ull && valid_after >= create &&
                               valid_after - create <= 3'600'000'000'000ull;
                if (!*t.has_header)
                    CPM_LOG_INFO("cpm_history: topic '%s' (type '%s') has no Header: its data time is the writer's "
                                 "source timestamp", t.name.c_str(), t.type_name.c_str());
            }
            const bool stamped = *t.has_header;
            const Oid oid = registry.instance(t.name, info.instance_handle, writer, [&] {
                std::string key = key_text(info.instance_handle, t.keyed);
                if (t.keyed && t.types) key = t.types->key_text(t.type_name, b.data(), b.size()).value_or(key);
                return Registry::Naming{key, t.type_name, stamped ? "create_stamp" : "source_timestamp"};
            }, now);
            if (oid == kNoOid) {  // millions of instances held at once: counted, not stored
                ++self.dropped_;
                continue;
            }
            out.commit(oid, {stamped ? u64(4) : source, stamped ? u64(12) : source, source, b.data(), b.size(), lost}, now);
        }
    }
};

Ingest::Ingest(const ServiceOptions& options, Outlet& out) : impl_(std::make_unique<Impl>(*this, options, out)) {}

void Ingest::rebuild() { impl_->rebuild(); }

bool Ingest::records(const std::string& topic) const
{
    std::lock_guard lock(mutex_);
    const auto it = impl_->topics.find(topic);
    return it != impl_->topics.end() && it->second->recorded;
}

Ingest::~Ingest()
{
    stop();
    impl_.reset();
}

void Ingest::stop()
{
    {
        std::lock_guard lock(impl_->clock.mutex);
        impl_->clock.stopping = true;
    }
    impl_->clock.changed.notify_all();
    std::lock_guard lock(impl_->events_mutex);
    impl_->stopping = true;
    impl_->events_cv.notify_all();
}

std::vector<std::string> Ingest::wait_for_clock(uint64_t t_ns, std::chrono::milliseconds timeout)
{
    auto& c = impl_->clock;
    std::unique_lock lock(c.mutex);
    auto behind = [&] {
        std::vector<std::string> out;
        for (const auto& [node, next] : c.announced) {
            if (next < t_ns && !c.given_up.count(node)) out.push_back(node);
        }
        return out;
    };
    if (c.changed.wait_for(lock, timeout, [&] { return c.stopping || behind().empty(); })) return {};
    auto late = behind();
    c.given_up.insert(late.begin(), late.end());
    return late;
}

bool Ingest::process_events(std::chrono::milliseconds wait)
{
    auto& d = *impl_;
    std::deque<Event> batch;
    {
        std::unique_lock lock(d.events_mutex);
        d.events_cv.wait_for(lock, wait, [&] { return d.stopping || !d.events.empty(); });
        if (d.stopping) return false;
        batch.swap(d.events);
    }
    const uint64_t now = cpm::get_time_ns();
    for (const auto& e : batch) {
        // Creating a reader takes Fast DDS locks that its receive threads hold while they
        // call ingest(): never under the lock.
        if (e.kind == Event::writer_found) {
            const bool known = locked([&] { return d.topics.count(e.writer.topic) != 0; });
            if (!known && (d.wanted(e.writer.topic) || d.clock_topic(e.writer.topic))) d.subscribe(e.writer);
        } else {
            locked([&] { d.handle(e, now); });
        }
    }
    return true;
}

size_t Ingest::topic_count() const
{
    std::lock_guard lock(mutex_);
    return size_t(std::count_if(impl_->topics.begin(), impl_->topics.end(), [](const auto& t) { return t.second->recorded; }));
}

uint64_t Ingest::received(const std::string& topic) const
{
    std::lock_guard lock(mutex_);
    const auto it = impl_->topics.find(topic);
    return it == impl_->topics.end() ? 0 : it->second->received;
}

std::vector<TopicCount> Ingest::topic_counts() const
{
    std::lock_guard lock(mutex_);
    std::vector<TopicCount> out;
    for (const auto& [name, t] : impl_->topics) {
        if (t->recorded) out.push_back({name, t->type_name, t->received, t->lost});
    }
    return out;
}

}  // namespace cpm::rtdb
