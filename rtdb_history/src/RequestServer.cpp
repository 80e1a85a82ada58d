#include "RequestServer.hpp"

#include <cpm/get_time_ns.hpp>
#include <cpm/rtdb/Requests.hpp>
#include <cpm/stamp_message.hpp>
#include <cpm/topics.hpp>

namespace cpm::rtdb {

RequestServer::RequestServer(const Store& store, Participant& participant, size_t workers)
    : store_(store),
      replies_(participant, topics::history_reply.name, topics::history_reply.writer)
{
    for (size_t i = 0; i < std::max<size_t>(1, workers); ++i) workers_.emplace_back([this] { work_loop(); });
    reader_ = std::make_unique<AsyncReader<HistoryRequest>>(
        [this](std::vector<HistoryRequest>& batch) {
            for (auto& rq : batch) {
                if (may_wait(rq)) {
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

RequestServer::~RequestServer()
{
    {
        std::lock_guard lock(work_mutex_);
        stopping_ = true;
        work_cv_.notify_all();
    }
    reader_->stop();
    for (auto& t : workers_) t.join();
}

void RequestServer::serve(const HistoryRequest& rq)
{
    HistoryReply reply = answer(store_, rq);
    cpm::stamp_message(reply, cpm::get_time_ns(), 0);
    ++requests_;
    const auto status = history::status_from(reply.status());
    if (status == history::Status::error || status == history::Status::unknown_object) ++bad_requests_;
    (void)replies_.write(reply);
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
