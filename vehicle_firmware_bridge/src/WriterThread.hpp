#pragma once
#include <cpm/Logging.hpp>
#include <cpm/Writer.hpp>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <string>
#include <thread>
#include <utility>

namespace cpm::vehicle {

/// Writes a loop's samples from a thread of its own, in order. A DDS write can stall for seconds -
/// Fast DDS 2.9 waits a second per send, again and again, on the shared-memory port of a reader
/// whose process was killed while holding that port's lock - and a car's loops (a simulated
/// microcontroller's clock and watchdog, the bridge's serial loop) must not wait for it, as a real
/// car never waits for the lab's network. While a write is held up, at most `capacity` samples
/// wait; older ones are dropped, and a warning says how many once the writes go through again.
/// On the lab's simulated clock (`own_thread` false) it writes on the caller's thread instead:
/// the clock waits for the samples anyway, and the runs repeat sample for sample.
template <class T>
class WriterThread
{
public:
    WriterThread(Writer<T>& writer, std::string topic, size_t capacity, bool own_thread)
        : writer_(writer), topic_(std::move(topic)), capacity_(capacity)
    {
        if (own_thread) thread_ = std::thread([this] { run(); });
    }
    /// Returns once a write under way has ended; the samples still waiting are dropped (the
    /// loop has stopped: not worth a stalled write each).
    ~WriterThread()
    {
        {
            std::lock_guard<std::mutex> lock(mutex_);
            running_ = false;
            waiting_.clear();
        }
        ready_.notify_one();
        if (thread_.joinable()) thread_.join();
    }
    WriterThread(const WriterThread&) = delete;
    WriterThread& operator=(const WriterThread&) = delete;

    /// Hands the sample over to be written; with a thread of its own, never waits for DDS.
    void write(const T& sample)
    {
        if (!thread_.joinable()) {
            (void)writer_.write(sample);
            return;
        }
        {
            std::lock_guard<std::mutex> lock(mutex_);
            if (waiting_.size() >= capacity_) {
                waiting_.pop_front();
                ++dropped_;
            }
            waiting_.push_back(sample);
        }
        ready_.notify_one();
    }

private:
    void run()
    {
        for (;;) {
            std::deque<T> batch;
            uint64_t dropped = 0;
            {
                std::unique_lock<std::mutex> lock(mutex_);
                ready_.wait(lock, [&] { return !waiting_.empty() || !running_; });
                if (!running_) return;
                batch.swap(waiting_);
                std::swap(dropped, dropped_);
            }
            if (dropped > 0) {
                const double held_up_s = std::exchange(longest_write_s_, 0.0);
                CPM_LOG_WARN("'%s': %llu samples were not published: a DDS write was held up for %.1f s (a reader's process "
                             "killed while holding its shared-memory port?) and only the newest %zu waited",
                             topic_.c_str(), static_cast<unsigned long long>(dropped), held_up_s, capacity_);
            }
            for (const auto& sample : batch) {
                const auto start = std::chrono::steady_clock::now();
                (void)writer_.write(sample);
                longest_write_s_ = std::max(longest_write_s_, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
            }
        }
    }

    Writer<T>& writer_;
    const std::string topic_;
    const size_t capacity_;
    std::mutex mutex_;
    std::condition_variable ready_;
    std::deque<T> waiting_;
    uint64_t dropped_ = 0;  ///< under mutex_, since the last warning
    double longest_write_s_ = 0;  ///< the writer thread's: the longest write since the last warning
    bool running_ = true;
    std::thread thread_;  // last: starts once the rest exists (none on the simulated clock)
};

}  // namespace cpm::vehicle
