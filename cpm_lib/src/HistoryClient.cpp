#include <cpm/AsyncReader.hpp>
#include <cpm/HistoryClient.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/stamp_message.hpp>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <map>
#include <mutex>
#include <random>
#include <set>
#include <unistd.h>

namespace cpm {

namespace {

WriterOptions request_options()
{
    WriterOptions o;
    o.reliable = true;
    o.history_depth = 64;
    return o;
}

ReaderOptions reply_options()
{
    ReaderOptions o;
    o.reliable = true;
    o.keep_all = true;
    o.transient_local = true;  // the service's replies written before this reader matched
    return o;
}

}  // namespace

struct HistoryClient::Impl
{
    std::string client_id;
    std::chrono::milliseconds reply_timeout;
    std::mutex mutex;
    std::condition_variable cv;
    std::map<uint64_t, HistoryReply> replies;  // arrived, not yet collected
    std::set<uint64_t> pending;                // asked, not yet answered
    std::atomic<uint64_t> next_id{1};
    Writer<HistoryRequest> requests;
    AsyncReader<HistoryReply> reader;

    Impl(Participant& p, std::chrono::milliseconds timeout)
        : client_id(std::to_string(::getpid()) + "-" + std::to_string(std::random_device{}())), reply_timeout(timeout),
          requests(p, "historyRequest", request_options()),
          reader(
              [this](std::vector<HistoryReply>& batch) {
                  std::lock_guard lock(mutex);
                  for (auto& r : batch) {
                      if (r.client_id() == client_id && pending.count(r.request_id())) replies[r.request_id()] = std::move(r);
                  }
                  cv.notify_all();
              },
              p, "historyReply", reply_options())
    {
    }
};

double update_rate_hz(const HistoryObject& o, uint64_t now_ns)
{
    if (o.is_process() || o.samples_held() == 0) return 0;
    const uint64_t end = o.deleted_ts() ? std::min(o.deleted_ts(), now_ns) : now_ns;
    const uint64_t start = std::max(o.created_ts(), end - std::min(end, o.history_interval_ns()));
    if (end < start + 1'000'000'000ull) return 0;  // too short to tell (or another machine's clock ahead of ours)
    return double(o.samples_held()) * 1e9 / double(end - start);
}

HistoryClient::HistoryClient(Participant& participant, std::chrono::milliseconds reply_timeout)
    : impl_(std::make_unique<Impl>(participant, reply_timeout))
{
}

HistoryClient::~HistoryClient() = default;

HistoryRequest HistoryClient::make(const std::string& kind, const std::string& topic, const std::string& key, uint64_t t0, HistoryBy by)
{
    HistoryRequest rq;
    rq.kind(kind);
    rq.topic(topic);
    rq.key(key);
    rq.t0(t0);
    rq.by(by == HistoryBy::data ? "data" : "commit");
    return rq;
}

HistoryReply HistoryClient::request(HistoryRequest rq)
{
    auto& d = *impl_;
    const auto deadline = std::chrono::steady_clock::now() + d.reply_timeout + std::chrono::nanoseconds(rq.timeout_ns());
    // A volatile request sent before the service's reader matched would be lost: wait for it.
    auto left = [&] { return std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now()); };
    if (!d.requests.wait_for_matched(1, left()) || !d.reader.wait_for_matched(1, left())) {
        throw Error("history: no history service answers on this domain (is cpm_history running?)");
    }
    const uint64_t id = d.next_id++;
    rq.client_id(d.client_id);
    rq.request_id(id);
    stamp_message(rq, get_time_ns(), 0);
    // Sent again each second without an answer (queries do not change what is stored; the
    // first reply to arrive is taken).
    std::unique_lock lock(d.mutex);
    d.pending.insert(id);
    struct Done
    {
        Impl& d;
        uint64_t id;
        ~Done()
        {
            d.pending.erase(id);
            d.replies.erase(id);
        }
    } done{d, id};
    for (;;) {
        lock.unlock();
        if (!d.requests.write(rq)) throw Error("history: the request could not be sent");
        lock.lock();
        const auto resend = std::min(deadline, std::chrono::steady_clock::now() + std::chrono::nanoseconds(rq.timeout_ns()) +
                                                   std::chrono::seconds(1));
        if (d.cv.wait_until(lock, resend, [&] { return d.replies.count(id) != 0; })) break;
        if (std::chrono::steady_clock::now() >= deadline) {
            throw Error("history: no reply to request " + std::to_string(id) + " (" + rq.kind() + ") in time");
        }
    }
    return std::move(d.replies[id]);
}

HistoryReply HistoryClient::latest(const std::string& topic, const std::string& key) { return request(make("latest", topic, key)); }

HistoryReply HistoryClient::at(const std::string& topic, const std::string& key, uint64_t t, HistoryBy by)
{
    return request(make("at", topic, key, t, by));
}

}  // namespace cpm
