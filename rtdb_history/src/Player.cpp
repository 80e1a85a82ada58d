#include <cpm/rtdb/Player.hpp>

#include <cpm/Error.hpp>
#include <cpm/nodes.hpp>
#include <cpm/percentile.hpp>
#include <cpm/topics.hpp>
#include <cpm/rtdb/IdlDecoder.hpp>

#include "RawType.hpp"
#include "Sqlite.hpp"

#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/publisher/qos/DataWriterQos.hpp>
#include <fastdds/dds/topic/Topic.hpp>

#include <algorithm>
#include <chrono>
#include <map>
#include <memory>
#include <regex>
#include <thread>

namespace cpm::rtdb {

namespace dds = eprosima::fastdds::dds;

const std::vector<std::string>& control_topics()
{
    static const std::vector<std::string> topics = nodes::control_topics();
    return topics;
}

bool is_control(const std::string& topic) { return nodes::matches(topic, control_topics()); }

struct Player::Impl
{
    Participant& participant;
    std::string path;
    PlayOptions options;
    sqlite3* db = nullptr;
    std::unique_ptr<IdlDecoder> types;
    dds::Publisher* publisher = nullptr;
    struct Out
    {
        std::string topic, type;
        dds::Topic* topic_entity = nullptr;
        dds::DataWriter* writer = nullptr;
    };
    std::map<std::string, Out> writers;  // by topic
    std::vector<std::pair<std::string, std::string>> topic_list;

    Impl(Participant& p, std::string file, PlayOptions o) : participant(p), path(std::move(file)), options(std::move(o)) {}
    ~Impl()
    {
        auto* dp = participant.native();
        for (auto& [name, w] : writers) {
            if (w.writer) {
                size_t removed = 0;  // an empty history first: see cpm::detail::WriterCore::close
                (void)w.writer->clear_history(&removed);
                publisher->delete_datawriter(w.writer);
            }
            if (w.topic_entity) dp->delete_topic(w.topic_entity);
        }
        if (publisher) dp->delete_publisher(publisher);
        sqlite3_close(db);
    }

    bool selected(const std::string& topic, const std::vector<std::regex>& include, const std::vector<std::regex>& exclude) const
    {
        for (const auto& r : exclude) {
            if (std::regex_match(topic, r)) return false;
        }
        if (include.empty()) return !is_control(topic);
        for (const auto& r : include) {
            if (std::regex_match(topic, r)) return true;
        }
        return false;
    }
};

Player::Player(Participant& participant, const std::string& path, PlayOptions options)
    : impl_(std::make_unique<Impl>(participant, path, std::move(options)))
{
    auto& im = *impl_;
    if (!(im.options.rate > 0)) throw cpm::Error("cpm play: the rate must be greater than 0");
    std::map<std::string, std::string> meta;
    im.db = open_recording_file(path, meta);
    auto compile = [](const std::vector<std::string>& patterns) {
        std::vector<std::regex> out;
        for (const auto& p : patterns) out.emplace_back(p);
        return out;
    };
    const auto include = compile(im.options.include), exclude = compile(im.options.exclude);
    std::map<std::string, std::string> idl;
    {
        sqlite::Statement t(im.db, "SELECT file, idl FROM types");
        while (t.step() == SQLITE_ROW) idl[t.text(0)] = t.text(1);
    }
    if (!idl.empty()) im.types = std::make_unique<IdlDecoder>(idl);
    // One writer per topic that has samples in the span and is selected; the type as recorded.
    std::map<std::string, std::pair<std::string, bool>> topics;  // topic → type, keyed
    {
        sqlite::Statement q(im.db, "SELECT DISTINCT topic, type_name, key != '' FROM objects WHERE kind = 'instance'");
        while (q.step() == SQLITE_ROW) {
            const std::string topic = q.text(0);
            if (!im.selected(topic, include, exclude)) continue;
            auto& t = topics[topic];
            t.first = q.text(1);
            t.second = t.second || q.u64(2) != 0;
        }
    }
    auto* dp = participant.native();
    im.publisher = dp->create_publisher(dds::PUBLISHER_QOS_DEFAULT);
    if (!im.publisher) throw cpm::Error("cpm play: DDS refused a publisher");
    for (const auto& [topic, t] : topics) {
        const auto& [type, keyed] = t;
        RawEndpoint e{topic, type, keyed || (im.types && !im.types->key_members(type).empty()), true, false};
        if (!register_raw_type(dp, e, im.types.get())) throw cpm::Error("cpm play: DDS refused the type " + type + " of topic " + topic);
        Impl::Out out{topic, type};
        out.topic_entity = dp->create_topic(topic, type, dds::TOPIC_QOS_DEFAULT);
        if (!out.topic_entity) throw cpm::Error("cpm play: DDS refused topic " + topic + " (type " + type + ")");
        dds::DataWriterQos qos = dds::DATAWRITER_QOS_DEFAULT;
        qos.reliability().kind = dds::RELIABLE_RELIABILITY_QOS;
        qos.durability().kind = dds::VOLATILE_DURABILITY_QOS;
        qos.history().kind = dds::KEEP_LAST_HISTORY_QOS;
        qos.history().depth = 5000;
        // Any number of keys (Fast DDS's default of 10 instances would refuse the eleventh car),
        // each its newest `depth`; 0 is "unlimited" in Fast DDS 2.9.
        qos.resource_limits().max_instances = 0;
        qos.resource_limits().max_samples = 0;
        qos.resource_limits().max_samples_per_instance = 5000;
        qos.endpoint().history_memory_policy = eprosima::fastrtps::rtps::DYNAMIC_REUSABLE_MEMORY_MODE;
        qos.data_sharing().off();
        // A topic whose readers in cpm ask for transient-local (fsmStatus, log, parameter, …)
        // is played as the lab's own writers offer it: a volatile writer matches no such reader
        // (the monitor showed no state machine and no log in a replay). The newest per key, as
        // the table says, is what a reader that joins during the replay gets.
        if (const auto* spec = cpm::topics::find(topic); spec && spec->writer.transient_local) {
            const int depth = std::max(spec->writer.history_depth, 1);
            qos.durability().kind = dds::TRANSIENT_LOCAL_DURABILITY_QOS;
            qos.history().depth = depth;
            qos.resource_limits().max_samples_per_instance = depth;
        }
        out.writer = im.publisher->create_datawriter(out.topic_entity, qos);
        if (!out.writer) throw cpm::Error("cpm play: DDS refused a writer on topic " + topic);
        im.writers.emplace(topic, out);
        im.topic_list.emplace_back(topic, type);
    }
}

Player::~Player() = default;

const std::vector<std::pair<std::string, std::string>>& Player::topics() const { return impl_->topic_list; }

PlayStats Player::run(const std::function<bool()>& stop)
{
    auto& im = *impl_;
    PlayStats stats;
    for (const auto& [topic, type] : im.topic_list) stats.topics.push_back(topic);
    // Readers first: a replay into nobody loses its first samples.
    const auto wait_until = std::chrono::steady_clock::now() + std::chrono::nanoseconds(im.options.wait_for_readers_ns);
    for (auto& [topic, w] : im.writers) {
        dds::PublicationMatchedStatus matched{};
        for (;;) {
            w.writer->get_publication_matched_status(matched);
            if (matched.current_count > 0 || std::chrono::steady_clock::now() >= wait_until || stop()) break;
            std::this_thread::sleep_for(std::chrono::milliseconds(10));
        }
        if (matched.current_count == 0) stats.topics_unread.push_back(topic);
    }

    sqlite::Statement q(im.db,
                        "SELECT o.topic, s.commit_ns, s.payload FROM samples s JOIN objects o ON o.oid = s.oid"
                        " WHERE s.commit_ns >= ? AND s.commit_ns <= ? AND o.kind = 'instance' ORDER BY s.rowid");
    q.bind(1, std::min<uint64_t>(im.options.from_ns, INT64_MAX)).bind(2, std::min<uint64_t>(im.options.to_ns, INT64_MAX));
    RawSample sample;
    std::vector<double> late;
    std::chrono::steady_clock::time_point start;
    int rc;
    while ((rc = q.step()) == SQLITE_ROW && !stop()) {
        auto it = im.writers.find(q.text(0));
        if (it == im.writers.end()) continue;
        const uint64_t commit = q.u64(1);
        const uint8_t* data = q.blob(2);
        sample.bytes.assign(data, data + q.bytes(2));
        if (stats.published + stats.failed == 0) {
            stats.first_commit_ns = commit;
            start = std::chrono::steady_clock::now();
        }
        // Commit times are per object strictly increasing, across objects nearly so (one
        // ingest thread): never earlier than the sample before.
        const uint64_t offset = commit > stats.first_commit_ns ? commit - stats.first_commit_ns : 0;
        const auto due = start + std::chrono::nanoseconds(uint64_t(double(offset) / im.options.rate));
        std::this_thread::sleep_until(due);
        const auto sent = std::chrono::steady_clock::now();
        if (it->second.writer->write(&sample)) ++stats.published;
        else ++stats.failed;
        late.push_back(double(std::chrono::duration_cast<std::chrono::nanoseconds>(sent - due).count()));
        stats.last_commit_ns = commit;
    }
    if (rc != SQLITE_ROW && rc != SQLITE_DONE) {
        throw cpm::Error("recording " + im.path + ": damaged after " + std::to_string(stats.published) +
                         " replayed samples: " + sqlite::sqlite_error(im.db, rc));
    }
    for (auto& [topic, w] : im.writers) w.writer->wait_for_acknowledgments({10, 0});
    if (!late.empty()) {
        stats.late_p50_ns = cpm::percentile(late, 0.50);
        stats.late_p99_ns = cpm::percentile(late, 0.99);
        stats.late_max_ns = *std::max_element(late.begin(), late.end());
    }
    return stats;
}

}  // namespace cpm::rtdb
