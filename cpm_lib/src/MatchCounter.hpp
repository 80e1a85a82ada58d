#pragma once
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <mutex>

namespace cpm::detail {

/// The current number of matched remote endpoints, updated from a DDS listener, and a
/// wait for it to reach a value.
class MatchCounter
{
public:
    void set(int current_count)
    {
        {
            std::lock_guard<std::mutex> lock(mutex_);
            count_ = current_count > 0 ? static_cast<size_t>(current_count) : 0;
        }
        changed_.notify_all();
    }
    size_t get() const
    {
        std::lock_guard<std::mutex> lock(mutex_);
        return count_;
    }
    bool wait_for_at_least(size_t n, std::chrono::nanoseconds timeout) const
    {
        std::unique_lock<std::mutex> lock(mutex_);
        return changed_.wait_for(lock, timeout, [&] { return count_ >= n; });
    }

private:
    mutable std::mutex mutex_;
    mutable std::condition_variable changed_;
    size_t count_ = 0;
};

}  // namespace cpm::detail
