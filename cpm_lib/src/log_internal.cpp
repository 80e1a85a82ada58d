#include "log_internal.hpp"
#include "realtime_internal.hpp"

#include <cpm/Logging.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/init.hpp>

#include <condition_variable>
#include <cstdio>
#include <deque>
#include <mutex>
#include <thread>

namespace cpm::detail {

void log_error(const std::string& message)
{
    std::fprintf(stderr, "[cpm error] %llu %s: %s\n", static_cast<unsigned long long>(get_time_ns()),
                 init_settings().node_id.c_str(), message.c_str());
}

namespace {

struct LaterQueue
{
    std::mutex mutex;
    std::condition_variable ready;
    std::deque<std::string> messages;
    bool started = false;
};

LaterQueue& later_queue()
{
    static LaterQueue* q = new LaterQueue;  // never destroyed: its thread may run until exit
    return *q;
}

}  // namespace

void log_warning_later(std::string message)
{
    LaterQueue& q = later_queue();
    std::lock_guard<std::mutex> lock(q.mutex);
    q.messages.push_back(std::move(message));
    q.ready.notify_one();
    if (q.started) return;
    q.started = true;
    std::thread([&q] {
        run_at_normal_priority();
        for (;;) {
            std::string m;
            {
                std::unique_lock<std::mutex> l(q.mutex);
                q.ready.wait(l, [&] { return !q.messages.empty(); });
                m = std::move(q.messages.front());
                q.messages.pop_front();
            }
            CPM_LOG_WARN("%s", m.c_str());
        }
    }).detach();
}

namespace {

std::string incompatible_qos_message(bool reader, const std::string& topic, int policy_id, bool our_reliable,
                                     bool our_transient_local)
{
    // Policy ids of DDS 1.4 §2.2.3 (Fast DDS's QosPolicyId_t).
    std::string policy, ours, theirs;
    switch (policy_id) {
    case 2:
        policy = "durability";
        ours = our_transient_local ? "transient_local" : "volatile";
        theirs = reader ? "volatile (it keeps nothing for late joiners)" : "transient_local or more";
        break;
    case 11:
        policy = "reliability";
        ours = our_reliable ? "reliable" : "best_effort";
        theirs = reader ? "best_effort" : "reliable";
        break;
    case 4: policy = "deadline"; break;
    case 6: policy = "ownership"; break;
    case 8: policy = "liveliness"; break;
    case 12: policy = "destination_order"; break;
    case 23: policy = "data_representation"; break;
    default: policy = "policy " + std::to_string(policy_id); break;
    }
    std::string text = std::string(reader ? "reader" : "writer") + " on topic '" + topic + "': a " +
                       (reader ? "writer" : "reader") + " with incompatible QoS (" + policy + ") will not be matched";
    if (!ours.empty()) {
        text += reader ? ": this reader requests " + ours + ", the writer offers " + theirs
                       : ": this writer offers " + ours + ", the reader requests " + theirs;
    }
    return text;
}

}  // namespace

void IncompatibleQos::report(int policy_id)
{
    {
        std::lock_guard<std::mutex> lock(mutex_);
        if (!reported_.insert(policy_id).second) return;
    }
    log_warning_later(incompatible_qos_message(reader_, topic_, policy_id, reliable_, transient_local_));
}

}  // namespace cpm::detail
