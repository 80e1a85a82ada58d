#include <cpm/AsyncReader.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/HistoryClient.hpp>
#include <cpm/stamp_message.hpp>
#include <cpm/topics.hpp>
#include <cpm/Writer.hpp>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <map>
#include <mutex>
#include <random>
#include <set>
#include <unistd.h>

namespace cpm {

/// The history service over DDS: requests on historyRequest, replies matched by client and
/// request id on historyReply (in a secured lab, samples of topic T on historyReply/T).
class ServiceBackend final : public HistoryBackend
{
    Participant& participant;
    std::string client_id;
    std::chrono::milliseconds reply_timeout;
    std::mutex mutex;
    std::condition_variable cv;
    std::map<uint64_t, HistoryReply> replies;  // arrived, not yet collected
    std::set<uint64_t> pending;                // asked, not yet answered
    std::atomic<uint64_t> next_id{1};
    Writer<HistoryRequest> requests;
    AsyncReader<HistoryReply> reader;
    std::mutex topic_readers_mutex;
    std::map<std::string, std::unique_ptr<AsyncReader<HistoryReply>>> topic_readers;  // secured: per topic

    void collect(std::vector<HistoryReply>& batch)
    {
        std::lock_guard lock(mutex);
        for (auto& r : batch) {
            if (r.client_id() == client_id && pending.count(r.request_id())) replies[r.request_id()] = std::move(r);
        }
        cv.notify_all();
    }

    /// In a secured lab: the reader of historyReply/TOPIC, made on first use. Throws cpm::Error
    /// naming the topic when this node's permissions do not let it read that topic's past.
    AsyncReader<HistoryReply>& topic_reader(const std::string& topic)
    {
        std::lock_guard lock(topic_readers_mutex);
        auto& r = topic_readers[topic];
        if (!r) {
            try {
                r = std::make_unique<AsyncReader<HistoryReply>>([this](std::vector<HistoryReply>& batch) { collect(batch); }, participant,
                                                               topics::history_reply_topic(topic), topics::history_reply.reader);
            } catch (const Error& e) {
                topic_readers.erase(topic);
                throw Error("history: the past of '" + topic + "' is not for this node: " + e.what());
            }
        }
        return *r;
    }

public:
    ServiceBackend(Participant& p, std::chrono::milliseconds timeout)
        : participant(p), client_id(std::to_string(::getpid()) + "-" + std::to_string(std::random_device{}())), reply_timeout(timeout),
          requests(p, topics::history_request.name, topics::history_request.writer),
          reader([this](std::vector<HistoryReply>& batch) { collect(batch); }, p, topics::history_reply.name, topics::history_reply.reader)
    {
    }

    HistoryReply request(const HistoryRequest& asked) override
    {
        HistoryRequest rq = asked;
        const auto deadline = std::chrono::steady_clock::now() + reply_timeout + std::chrono::nanoseconds(rq.timeout_ns());
        // A volatile request sent before the service's reader matched would be lost: wait for it.
        auto left = [&] { return std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now()); };
        if (!requests.wait_for_matched(1, left()) || !reader.wait_for_matched(1, left())) {
            throw Error("history: no history service answers on this domain (is cpm_history running?)");
        }
        // Secured: the reply comes on historyReply/TOPIC, whose writer the service makes on the first
        // request for TOPIC; it keeps its last replies for readers that match later.
        if (participant.secured() && !rq.topic().empty()) (void)topic_reader(rq.topic());
        const uint64_t id = next_id++;
        rq.client_id(client_id);
        rq.request_id(id);
        stamp_message(rq, get_time_ns(), 0);
        // Sent again each second without an answer. A service that matches while we wait (one
        // started again after a crash: its dead predecessor stays matched until its lease ends and
        // got the request) may not know our writer yet when we know its reader, and drops what
        // comes before: it goes again at once, and a query that does not wait every 100 ms for a
        // second after each new match (a waiting one would hold a worker of the service per copy).
        // Queries do not change what is stored; the first reply to arrive is taken.
        using Clock = std::chrono::steady_clock;
        auto services = [&] { return requests.matched_subscriptions() + reader.matched_publications(); };
        size_t known = services();
        Clock::time_point matched_at{};
        Clock::time_point next_send = Clock::now();
        std::unique_lock lock(mutex);
        pending.insert(id);
        struct Done
        {
            ServiceBackend& d;
            uint64_t id;
            ~Done()
            {
                d.pending.erase(id);
                d.replies.erase(id);
            }
        } done{*this, id};
        auto answered = [&] { return replies.count(id) != 0; };
        while (!answered()) {
            if (Clock::now() >= next_send) {
                lock.unlock();
                if (!requests.write(rq)) throw Error("history: the request could not be sent");
                lock.lock();
                const auto now = Clock::now();
                next_send = rq.timeout_ns() == 0 && now < matched_at + std::chrono::seconds(1)
                                ? now + std::chrono::milliseconds(100)
                                : now + std::chrono::nanoseconds(rq.timeout_ns()) + std::chrono::seconds(1);
            }
            if (cv.wait_until(lock, std::min({next_send, deadline, Clock::now() + std::chrono::milliseconds(10)}), answered)) break;
            const size_t now_known = services();
            if (now_known > known) next_send = matched_at = Clock::now();
            known = now_known;  // also down, when a service leaves
            if (Clock::now() >= deadline) {
                throw Error("history: no reply to request " + std::to_string(id) + " (" + rq.kind() + ") in time" +
                            (participant.secured() && !rq.topic().empty()
                                 ? " (secured: the service answers on " + topics::history_reply_topic(rq.topic()) +
                                       ", which its permissions must let it publish: historyReply*)"
                                 : std::string()));
            }
        }
        return std::move(replies[id]);
    }
};

double update_rate_hz(const HistoryObject& o, uint64_t now_ns)
{
    if (o.is_process() || o.samples_held() == 0) return 0;
    const uint64_t end = o.deleted_ts() ? std::min(o.deleted_ts(), now_ns) : now_ns;
    // Over the window the object holds, or, where its samples reach further back (a recording
    // keeps every sample of its run), over the time they span.
    uint64_t start = end - std::min(end, o.history_interval_ns());
    if (o.oldest_commit_ns() != 0) start = std::min(start, o.oldest_commit_ns());
    start = std::max(o.created_ts(), start);
    if (end < start + 1'000'000'000ull) return 0;  // too short to tell (or another machine's clock ahead of ours)
    return double(o.samples_held()) * 1e9 / double(end - start);
}

std::unique_ptr<HistoryBackend> history_service_backend(Participant& participant, std::chrono::milliseconds reply_timeout)
{
    return std::make_unique<ServiceBackend>(participant, reply_timeout);
}

HistoryClient::HistoryClient(Participant& participant, std::chrono::milliseconds reply_timeout)
    : backend_(history_service_backend(participant, reply_timeout))
{
}

HistoryClient::HistoryClient(std::unique_ptr<HistoryBackend> backend) : backend_(std::move(backend))
{
    if (!backend_) throw Error("HistoryClient: no backend given");
}

HistoryClient::~HistoryClient() = default;
HistoryClient::HistoryClient(HistoryClient&&) noexcept = default;
HistoryClient& HistoryClient::operator=(HistoryClient&&) noexcept = default;

HistoryReply HistoryClient::request(const HistoryRequest& rq) { return backend_->request(rq); }

history::Status HistoryClient::status_of(const std::string& wire, std::string& error)
{
    if (auto s = history::status_from(wire)) return *s;
    error = "the answer's status '" + wire + "' is not one this program knows";
    return history::Status::error;
}

HistoryRequest HistoryClient::make(history::Kind kind, const std::string& topic, const std::string& key, uint64_t t0, HistoryBy by)
{
    HistoryRequest rq;
    rq.kind(std::string(history::to_string(kind)));
    rq.topic(topic);
    rq.key(key);
    rq.t0(t0);
    rq.by(std::string(history::to_string(by)));
    return rq;
}

HistoryReply HistoryClient::latest(const std::string& topic, const std::string& key) { return request(make(history::Kind::latest, topic, key)); }

HistoryReply HistoryClient::at(const std::string& topic, const std::string& key, uint64_t t, HistoryBy by)
{
    return request(make(history::Kind::at, topic, key, t, by));
}

}  // namespace cpm
