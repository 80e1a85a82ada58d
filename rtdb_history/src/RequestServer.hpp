#pragma once
// The history service's request side: answers historyRequest from the store on historyReply.
// Requests that may wait (wait_next, successor, wait_object) go to worker threads so that they
// never hold up the others.
#include <cpm/AsyncReader.hpp>
#include <cpm/Participant.hpp>
#include <cpm/Writer.hpp>
#include <cpm/rtdb/Store.hpp>

#include <HistoryReply.h>
#include <HistoryRequest.h>

#include <atomic>
#include <condition_variable>
#include <deque>
#include <functional>
#include <list>
#include <map>
#include <string>
#include <memory>
#include <mutex>
#include <set>
#include <thread>
#include <vector>

namespace cpm::rtdb {

class RequestServer
{
public:
    /// Answers a `save` request (it takes as long as the span after now); none: refused.
    using SaveHandler = std::function<HistoryReply(const HistoryRequest&)>;
    RequestServer(const Store& store, Participant& participant, size_t workers, SaveHandler save = {});
    ~RequestServer();
    RequestServer(const RequestServer&) = delete;
    RequestServer& operator=(const RequestServer&) = delete;

    /// Answers no more requests (those being answered are finished); the counts are final.
    void stop();

    uint64_t requests() const { return requests_; }
    uint64_t bad_requests() const { return bad_requests_; }

private:
    void serve(const HistoryRequest& rq);
    void send(HistoryReply reply, const HistoryRequest& rq);
    void work_loop();
    /// Secured: the writer of historyReply/TOPIC, made on first use.
    Writer<HistoryReply>& topic_writer(const std::string& topic);

    const Store& store_;
    Participant& participant_;
    std::atomic<uint64_t> requests_{0}, bad_requests_{0};
    Writer<HistoryReply> replies_;
    std::mutex topic_writers_mutex_;
    std::map<std::string, std::unique_ptr<Writer<HistoryReply>>> topic_writers_;
    std::mutex work_mutex_;
    std::condition_variable work_cv_;
    std::deque<HistoryRequest> work_;
    bool stopping_ = false;
    std::vector<std::thread> workers_;
    SaveHandler save_;
    struct Saving
    {
        std::thread thread;
        std::shared_ptr<std::atomic<bool>> done;
    };
    std::list<Saving> saves_;  // each save on a thread of its own: finished ones joined at the next, all at stop()
    std::set<std::pair<std::string, uint64_t>> saves_seen_;  // (client, request): each save once (the recent ones)
    std::unique_ptr<AsyncReader<HistoryRequest>> reader_;
};

}  // namespace cpm::rtdb
