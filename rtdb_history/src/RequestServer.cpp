#include "RequestServer.hpp"

#include <cpm/get_time_ns.hpp>
#include <cpm/rtdb/Requests.hpp>
#include <cpm/stamp_message.hpp>
#include <cpm/topics.hpp>

namespace cpm::rtdb {

RequestServer::RequestServer(const Store& store, Participant& participant, size_t workers, SaveHandler save)
    : store_(store), participant_(participant),
      replies_(participant, topics::history_reply.name, topics::history_reply.writer), save_(std::move(save))
{
    for (size_t i = 0; i < std::max<size_t>(1, workers); ++i) workers_.emplace_back([this] { work_loop(); });
    reader_ = std::make_unique<AsyncReader<HistoryRequest>>(
        [this](std::vector<HistoryRequest>& batch) {
            for (auto& rq : batch) {
                if (rq.kind() == "save" && save_) {  // it lasts the span after now: on a thread of its own
                    std::lock_guard lock(work_mutex_);
                    // A client sends a request again when a service matches while it waits: one save each.
                    for (auto it = saves_.begin(); it != saves_.end();) {  // the finished ones
                        if (!*it->done) {
                            ++it;
                            continue;
                        }
                        it->thread.join();
                        it = saves_.erase(it);
                    }
                    if (saves_seen_.size() > 4096) saves_seen_.clear();  // a client resends within seconds, not hours
                    if (!stopping_ && saves_seen_.emplace(rq.client_id(), rq.request_id()).second) {
                        auto done = std::make_shared<std::atomic<bool>>(false);
                        saves_.push_back({std::thread([this, rq, done] {
                                              send(save_(rq), rq);
                                              *done = true;
                                          }),
                                          done});
                    }
                } else if (may_wait(rq)) {
                    std::lock_guard lock(work_mutex_);
                    work_.push_back(std::move(rq));
                    work_cv_.notify_one();
                } else {
                    serve(rq);
                }
            }
        },
        participant, topics::history_request.name, topics::history_request.reader);
}

RequestServer::~RequestServer() { stop(); }

void RequestServer::stop()
{
    {
        std::lock_guard lock(work_mutex_);
        stopping_ = true;
        work_cv_.notify_all();
    }
    reader_->stop();
    for (auto& t : workers_) {
        if (t.joinable()) t.join();
    }
    for (auto& t : saves_) {
        if (t.thread.joinable()) t.thread.join();
    }
}

void RequestServer::serve(const HistoryRequest& rq) { send(answer(store_, rq), rq); }

void RequestServer::send(HistoryReply reply, const HistoryRequest& rq)
{
    cpm::stamp_message(reply, cpm::get_time_ns(), 0);
    ++requests_;
    const auto status = history::status_from(reply.status());
    if (status == history::Status::error || status == history::Status::unknown_object) ++bad_requests_;
    if (!participant_.secured() || reply.samples().empty()) {
        (void)replies_.write(reply);
        return;
    }
    // Secured: samples go out only on historyReply/T, readable by the nodes that may subscribe T,
    // and only samples of the topic the request names (an oid alone, or several topics, would
    // let a reply carry a topic other than the one it goes out on).
    const std::string& topic = rq.topic();
    bool one_topic = !topic.empty();
    for (const auto& o : reply.objects()) one_topic = one_topic && (o.topic() == topic || o.is_process());
    if (!one_topic) {
        HistoryReply refused;
        refused.client_id(rq.client_id());
        refused.request_id(rq.request_id());
        refused.status(std::string(history::to_string(history::Status::error)));
        refused.error("in a secured lab a query for samples names its topic (topic), and is answered from that topic only");
        cpm::stamp_message(refused, cpm::get_time_ns(), 0);
        ++bad_requests_;
        (void)replies_.write(refused);
        return;
    }
    (void)topic_writer(topic).write(reply);
}

Writer<HistoryReply>& RequestServer::topic_writer(const std::string& topic)
{
    std::lock_guard lock(topic_writers_mutex_);
    auto& w = topic_writers_[topic];
    if (!w) w = std::make_unique<Writer<HistoryReply>>(participant_, topics::history_reply_topic(topic), topics::history_reply.writer);
    return *w;
}

void RequestServer::work_loop()
{
    for (;;) {
        HistoryRequest rq;
        {
            std::unique_lock lock(work_mutex_);
            work_cv_.wait(lock, [&] { return !work_.empty() || stopping_; });
            if (stopping_) return;
            rq = std::move(work_.front());
            work_.pop_front();
        }
        serve(rq);
    }
}

}  // namespace cpm::rtdb
