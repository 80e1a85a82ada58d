#include <cpm/rtdb/HistoryService.hpp>

#include <cpm/AsyncReader.hpp>
#include <cpm/Error.hpp>
#include <cpm/Logging.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/rtdb/IdlDecoder.hpp>
#include <cpm/rtdb/Requests.hpp>
#include <cpm/stamp_message.hpp>

#include <HistoryReply.h>
#include <HistoryRequest.h>
#include <HistoryStatus.h>
#include <cpm_topic_types.hpp>

#include "RawType.hpp"

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantListener.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastrtps/xmlparser/XMLProfileManager.h>

#include <condition_variable>
#include <deque>
#include <map>
#include <mutex>
#include <regex>
#include <set>
#include <sstream>
#include <stdexcept>
#include <thread>


namespace cpm::rtdb {

namespace dds = eprosima::fastdds::dds;
namespace rtps = eprosima::fastrtps::rtps;

namespace {

std::string prefix_text(const rtps::GuidPrefix_t& p)
{
    std::ostringstream s;
    s << p;
    return s.str();
}

/// The instance key as cpm prints it: a lab type's vehicle id (the one-byte key the handle
/// starts with), otherwise the handle in hex; "" for an unkeyed topic.
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
    std::string topic, type_name, name;
    bool keyed = false, reliable = false, transient_local = false;
    rtps::GUID_t guid;
};

}  // namespace

struct HistoryService::Impl : public dds::DomainParticipantListener
{
    /// What the service knows of an instance it records.
    struct InstanceRec
    {
        Oid oid = kNoOid;
        std::set<rtps::GUID_t> writers;
        bool deleted = false;
    };
    /// One recorded topic: a raw reader on the recording participant, and its instances.
    struct TopicRec : public dds::DataReaderListener
    {
        Impl* service = nullptr;
        std::string name, type_name;
        bool keyed = false;
        const IdlDecoder* types = nullptr;  ///< the lab's IDL when it describes the type: keys and stamps exact
        std::optional<bool> has_header;  ///< decided from the IDL, else from the first sample
        dds::Topic* topic = nullptr;
        dds::DataReader* reader = nullptr;
        uint64_t received = 0, received_at_last_status = 0, lost = 0;
        std::map<rtps::GUID_t, uint64_t> last_sequence;  ///< per writer: the newest sequence number taken
        std::map<rtps::InstanceHandle_t, InstanceRec> instances;  // under ingest_mutex
        void on_data_available(dds::DataReader* r) override { service->ingest(*this, r); }
    };
    /// A participant seen: its object and name.
    struct ProcessRec
    {
        Oid oid = kNoOid;
        std::string name;
    };

    ServiceOptions options;
    Store store_;
    std::vector<std::regex> include, exclude;

    std::unique_ptr<Participant> recorder;  // raw readers only
    Participant* serving = nullptr;          // request, reply, status
    std::unique_ptr<Participant> own_serving;  // serving, when the options name one
    dds::Subscriber* raw_subscriber = nullptr;

    std::mutex events_mutex;
    std::condition_variable events_cv;
    std::deque<Event> events;
    std::atomic<bool> stopping{false};  ///< set (then both condition variables notified) by the destructor

    // The ingest path (reader callbacks, discovery handling, expiry) under one lock.
    std::mutex ingest_mutex;
    std::map<std::string, std::unique_ptr<TopicRec>> topics;
    std::map<rtps::GuidPrefix_t, ProcessRec> processes;
    std::atomic<uint64_t> received{0}, dropped{0}, lost{0}, requests{0}, bad_requests{0};

    std::unique_ptr<Writer<HistoryReply>> replies;
    std::unique_ptr<Writer<HistoryStatus>> status;
    std::unique_ptr<AsyncReader<HistoryRequest>> request_reader;
    std::mutex work_mutex;
    std::condition_variable work_cv;
    std::deque<HistoryRequest> work;
    std::vector<std::thread> workers;
    std::thread control;

    explicit Impl(ServiceOptions o) : options(std::move(o)), store_(StoreOptions{{options.window_ns, options.max_bytes_per_topic}, options.max_bytes})
    {
        auto compile = [](const std::vector<std::string>& patterns, const char* flag) {
            std::vector<std::regex> out;
            for (const auto& p : patterns) {
                try {
                    out.emplace_back(p);
                } catch (const std::regex_error& e) {
                    throw Error(std::string(flag) + " '" + p + "' is not a regular expression: " + e.what());
                }
            }
            return out;
        };
        for (const auto& [topic, window] : options.topic_windows_ns) store_.set_retention(topic, {window, options.max_bytes_per_topic});
        include = compile(options.include, "--include");
        exclude = compile(options.exclude, "--exclude");
    }

    void start()
    {
        // Fast DDS 2.9 delivers between participants of one process by direct calls. After the
        // process was stopped for longer than a lease (SIGSTOP, a debugger, a stalled VM) the
        // reliable path from the service's own writers (historyStatus, its log) to its recorder
        // never delivers again, while the same writers still reach other processes. Through
        // the transports, as from every other process, it recovers: the service pays one
        // loopback hop for its own few samples a second.
        auto library = eprosima::fastrtps::xmlparser::XMLProfileManager::library_settings();
        library.intraprocess_delivery = eprosima::fastrtps::INTRAPROCESS_OFF;
        eprosima::fastrtps::xmlparser::XMLProfileManager::library_settings(library);
        ParticipantOptions rec = options.participant.value_or(ParticipantOptions::from_init());
        rec.name = (rec.name.empty() ? std::string("cpm_history") : rec.name) + "_recorder";
        rec.discovery_listener = this;
        recorder = std::make_unique<Participant>(rec);
        raw_subscriber = recorder->native()->create_subscriber(dds::SUBSCRIBER_QOS_DEFAULT);
        if (!raw_subscriber) throw Error("cpm_history: cannot create the recording subscriber");
        if (options.participant) {
            ParticipantOptions srv = *options.participant;
            if (srv.name.empty()) srv.name = "cpm_history";
            own_serving = std::make_unique<Participant>(srv);
            serving = own_serving.get();
        } else {
            serving = &Participant::default_participant();
        }
        // Transient-local: a client whose reader the writer has not matched yet when the reply
        // goes out still gets it on matching.
        replies = std::make_unique<Writer<HistoryReply>>(*serving, "historyReply",
                                                         WriterOptions{.reliable = true, .history_depth = 64, .transient_local = true});
        status = std::make_unique<Writer<HistoryStatus>>(*serving, "historyStatus",
                                                          WriterOptions{.reliable = true, .history_depth = 1, .transient_local = true});
        for (size_t i = 0; i < std::max<size_t>(1, options.workers); ++i) workers.emplace_back([this] { work_loop(); });
        request_reader = std::make_unique<AsyncReader<HistoryRequest>>(
            [this](std::vector<HistoryRequest>& batch) {
                for (auto& rq : batch) {
                    if (may_wait(rq)) {
                        std::lock_guard lock(work_mutex);
                        work.push_back(std::move(rq));
                        work_cv.notify_one();
                    } else {
                        serve(rq);
                    }
                }
            },
            *serving, "historyRequest", ReaderOptions{.reliable = true, .keep_all = true});
        control = std::thread([this] { control_loop(); });
    }

    ~Impl() override
    {
        {
            std::lock_guard lock(events_mutex);
            stopping = true;
            events_cv.notify_all();
        }
        {
            std::lock_guard lock(work_mutex);
            work_cv.notify_all();
        }
        if (request_reader) request_reader->stop();
        for (auto& t : workers) t.join();
        if (control.joinable()) control.join();
        // Readers first, while their listeners (TopicRec) still exist.
        if (recorder) {
            for (auto& [name, t] : topics) {
                if (t->reader) {
                    t->reader->set_listener(nullptr);
                    raw_subscriber->delete_datareader(t->reader);
                }
                if (t->topic) recorder->native()->delete_topic(t->topic);
            }
            recorder->native()->delete_subscriber(raw_subscriber);
            recorder->native()->set_listener(nullptr);
        }
    }

    // ---- requests --------------------------------------------------------------------------
    void serve(const HistoryRequest& rq)
    {
        HistoryReply reply = answer(store_, rq);
        cpm::stamp_message(reply, cpm::get_time_ns(), 0);
        ++requests;
        if (reply.status() == "error" || reply.status() == "unknown_object") ++bad_requests;
        (void)replies->write(reply);
    }

    void work_loop()
    {
        for (;;) {
            HistoryRequest rq;
            {
                std::unique_lock lock(work_mutex);
                work_cv.wait(lock, [&] { return !work.empty() || stopping; });
                if (work.empty()) return;
                rq = std::move(work.front());
                work.pop_front();
            }
            serve(rq);
        }
    }

    // ---- discovery -------------------------------------------------------------------------
    void push(Event e)
    {
        std::lock_guard lock(events_mutex);
        events.push_back(std::move(e));
        events_cv.notify_one();
    }

    void on_participant_discovery(dds::DomainParticipant*, rtps::ParticipantDiscoveryInfo&& info) override
    {
        Event e{};
        e.guid = info.info.m_guid;
        e.name = info.info.m_participantName.to_string();
        switch (info.status) {
        case rtps::ParticipantDiscoveryInfo::DISCOVERED_PARTICIPANT: e.kind = Event::process_found; break;
        case rtps::ParticipantDiscoveryInfo::REMOVED_PARTICIPANT:
        case rtps::ParticipantDiscoveryInfo::DROPPED_PARTICIPANT: e.kind = Event::process_gone; break;
        default: return;
        }
        push(std::move(e));
    }

    void on_publisher_discovery(dds::DomainParticipant*, rtps::WriterDiscoveryInfo&& info) override
    {
        Event e{};
        e.guid = info.info.guid();
        e.topic = info.info.topicName().to_string();
        e.type_name = info.info.typeName().to_string();
        e.keyed = info.info.topicKind() == rtps::WITH_KEY;
        e.reliable = info.info.m_qos.m_reliability.kind == dds::RELIABLE_RELIABILITY_QOS;
        e.transient_local = info.info.m_qos.m_durability.kind != dds::VOLATILE_DURABILITY_QOS;
        switch (info.status) {
        case rtps::WriterDiscoveryInfo::DISCOVERED_WRITER: e.kind = Event::writer_found; break;
        case rtps::WriterDiscoveryInfo::REMOVED_WRITER: e.kind = Event::writer_gone; break;
        default: return;
        }
        push(std::move(e));
    }

    bool wanted(const std::string& topic) const
    {
        if (topic == "historyRequest" || topic == "historyReply") return false;
        for (const auto& re : exclude) {
            if (std::regex_match(topic, re)) return false;
        }
        if (include.empty()) return true;
        for (const auto& re : include) {
            if (std::regex_match(topic, re)) return true;
        }
        return false;
    }

    void handle(const Event& e)
    {
        const uint64_t now = cpm::get_time_ns();
        switch (e.kind) {
        case Event::process_found: {
            // A participant seen again after it was lost (its lease ran out while this process
            // or it was stopped) is a new process object, as in KogMo-RTDB.
            if (auto known = processes.find(e.guid.guidPrefix); known != processes.end()) {
                auto info = store_.info(known->second.oid);
                if (info && info->deleted_ts == 0) return;
            }
            processes[e.guid.guidPrefix] = {store_.add_object({.kind = ObjectKind::process, .name = e.name, .type_name = "participant",
                                                               .creator = e.name, .creator_guid = prefix_text(e.guid.guidPrefix),
                                                               .created_ts = now}),
                                            e.name};
            return;
        }
        case Event::process_gone: {
            auto it = processes.find(e.guid.guidPrefix);
            if (it != processes.end()) store_.mark_deleted(it->second.oid, now);
            // Its writers are gone with it.
            for (auto& [name, t] : topics) {
                for (auto& [handle, inst] : t->instances) {
                    std::erase_if(inst.writers, [&](const rtps::GUID_t& w) { return w.guidPrefix == e.guid.guidPrefix; });
                    if (inst.writers.empty() && !inst.deleted) delete_instance(inst, now);
                }
            }
            return;
        }
        case Event::writer_gone: {
            auto t = topics.find(e.topic);
            if (t == topics.end()) return;
            for (auto& [handle, inst] : t->second->instances) {
                if (inst.writers.erase(e.guid) && inst.writers.empty() && !inst.deleted) delete_instance(inst, now);
            }
            return;
        }
        case Event::writer_found: return;  // control_loop subscribes, outside ingest_mutex
        }
    }

    void delete_instance(InstanceRec& inst, uint64_t now)
    {
        inst.deleted = true;
        store_.mark_deleted(inst.oid, now);
    }

    void subscribe(const Event& e)
    {
        auto rec = std::make_unique<TopicRec>();
        rec->service = this;
        rec->name = e.topic;
        rec->type_name = e.type_name;
        rec->keyed = e.keyed;
        const IdlDecoder* types = IdlDecoder::lab_types();
        if (types && types->knows(e.type_name)) {
            rec->types = types;
            rec->has_header = types->has_header(e.type_name);
        }
        auto* participant = recorder->native();
        if (participant->find_type(e.type_name).empty()) {
            dds::TypeSupport type(new RawType(e.type_name, e.keyed, types));
            type->auto_fill_type_information(false);
            type->auto_fill_type_object(false);
            if (type.register_type(participant) != ReturnCode_t::RETCODE_OK) {
                CPM_LOG_ERROR("cpm_history: cannot register type '%s' of topic '%s'; not recorded", e.type_name.c_str(), e.topic.c_str());
                return;
            }
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
        CPM_LOG_INFO("cpm_history: recording topic '%s' (type '%s'%s)", e.topic.c_str(), e.type_name.c_str(), e.keyed ? ", keyed" : "");
        std::lock_guard lock(ingest_mutex);
        topics[e.topic] = std::move(rec);
    }

    // ---- ingest ----------------------------------------------------------------------------
    void ingest(TopicRec& t, dds::DataReader* reader)
    {
        Skipped skipped;
        {
            std::lock_guard lock(ingest_mutex);
            take_all(t, reader, skipped);
        }
        // Logged outside the lock: the log topic is recorded too, and Fast DDS delivers a write
        // to a reader in this process on the writing thread, which would take the lock again.
        for (size_t i = 0; i < skipped.count; ++i) {
            CPM_LOG_WARN("cpm_history: topic '%s': a sample of %zu bytes is too short to hold a Header (4 + 16 bytes); skipped",
                         t.name.c_str(), skipped.size);
        }
    }

    struct Skipped
    {
        size_t count = 0, size = 0;  ///< too short to hold a header (the first ten), and the last one's size
    };

    /// Takes every sample the reader holds into the store; under ingest_mutex.
    void take_all(TopicRec& t, dds::DataReader* reader, Skipped& skipped)
    {
        RawSample raw;
        dds::SampleInfo info;
        while (reader->take_next_sample(&raw, &info) == ReturnCode_t::RETCODE_OK) {
            const uint64_t now = cpm::get_time_ns();
            rtps::GUID_t writer;
            rtps::iHandle2GUID(writer, info.publication_handle);
            // A writer numbers everything it sends: a jump means samples that never arrived
            // (a best-effort sample dropped, a reliable writer's history overwritten while the
            // service could not keep up). Counted, and marked before the next one of the object.
            const uint64_t seq = info.sample_identity.sequence_number().to64long();
            uint64_t lost_before = 0;
            if (auto last = t.last_sequence.find(writer); last != t.last_sequence.end()) {
                if (seq > last->second + 1) lost_before = seq - last->second - 1;
                last->second = std::max(last->second, seq);
            } else {
                t.last_sequence.emplace(writer, seq);
            }
            t.lost += lost_before;
            lost += lost_before;
            if (!info.valid_data) {
                auto it = t.instances.find(info.instance_handle);
                if (it != t.instances.end() && !it->second.deleted && info.instance_state != dds::ALIVE_INSTANCE_STATE) {
                    delete_instance(it->second, now);
                }
                continue;
            }
            ++t.received;
            ++received;
            const auto& b = raw.bytes;
            if (b.size() < 4 + 16) {  // encapsulation + Header
                if (++dropped <= 10) {
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
            const uint64_t source = uint64_t(info.source_timestamp.seconds()) * 1'000'000'000ull + info.source_timestamp.nanosec();
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
            auto& inst = t.instances[info.instance_handle];
            if (inst.oid == kNoOid || inst.deleted) {
                auto proc = processes.find(writer.guidPrefix);
                const ProcessRec creator = proc == processes.end() ? ProcessRec{} : proc->second;
                inst = InstanceRec{};
                std::string key = key_text(info.instance_handle, t.keyed);
                if (t.keyed && t.types) key = t.types->key_text(t.type_name, b.data(), b.size()).value_or(key);
                try {
                    inst.oid = store_.add_object({.topic = t.name, .key = key, .type_name = t.type_name,
                                                  .parent = creator.oid, .creator = creator.name,
                                                  .creator_guid = prefix_text(writer.guidPrefix), .created_ts = now,
                                                  .data_time = *t.has_header ? "create_stamp" : "source_timestamp"});
                } catch (const std::length_error&) {  // millions of instances held at once: counted, not stored
                    ++dropped;
                    continue;
                }
            }
            inst.writers.insert(writer);
            const bool stamped = *t.has_header;
            store_.commit(inst.oid, {stamped ? u64(4) : source, stamped ? u64(12) : source, source, b.data(), b.size(), lost_before},
                          now);
        }
    }

    // ---- housekeeping ----------------------------------------------------------------------
    void control_loop()
    {
        uint64_t next_status = 0;
        for (;;) {
            std::deque<Event> batch;
            {
                std::unique_lock lock(events_mutex);
                events_cv.wait_for(lock, std::chrono::milliseconds(100), [&] { return stopping || !events.empty(); });
                if (stopping) return;
                batch.swap(events);
            }
            const uint64_t now = cpm::get_time_ns();
            for (const auto& e : batch) {
                // Creating a reader takes Fast DDS locks that its receive threads hold while
                // they call ingest(): never under ingest_mutex.
                if (e.kind == Event::writer_found) {
                    bool known;
                    {
                        std::lock_guard lock(ingest_mutex);
                        known = topics.count(e.topic) != 0;
                    }
                    if (!known && wanted(e.topic)) subscribe(e);
                } else {
                    std::lock_guard lock(ingest_mutex);
                    handle(e);
                }
            }
            {
                std::lock_guard lock(ingest_mutex);
                store_.expire(now);
            }
            if (now >= next_status) {
                publish_status(now);
                next_status = now + options.status_period_ns;
            }
        }
    }

    void publish_status(uint64_t now)
    {
        HistoryStatus s;
        cpm::stamp_message(s, now, 0);
        s.service(serving ? "cpm_history" : "");
        auto st = store_.stats();
        s.objects(st.objects);
        s.alive(st.alive);
        s.samples(st.samples);
        s.bytes(st.bytes);
        s.evicted(st.evicted);
        s.dropped(dropped);
        s.lost(lost);
        s.requests(requests);
        s.bad_requests(bad_requests);
        {
            std::lock_guard lock(ingest_mutex);
            const double period_s = double(options.status_period_ns) * 1e-9;
            for (auto& [name, t] : topics) {
                HistoryTopicStatus ts;
                ts.topic(name);
                ts.type_name(t->type_name);
                ts.samples(t->received);
                ts.lost(t->lost);
                ts.rate_hz(double(t->received - t->received_at_last_status) / period_s);
                t->received_at_last_status = t->received;
                s.topics().push_back(ts);
            }
        }
        (void)status->write(s);
    }
};

HistoryService::HistoryService(ServiceOptions options) : impl_(std::make_unique<Impl>(std::move(options))) { impl_->start(); }

HistoryService::~HistoryService() = default;

const Store& HistoryService::store() const { return impl_->store_; }

ServiceCounters HistoryService::counters() const
{
    std::lock_guard lock(impl_->ingest_mutex);
    return {impl_->topics.size(), impl_->received, impl_->dropped, impl_->requests, impl_->bad_requests, impl_->lost};
}

}  // namespace cpm::rtdb
