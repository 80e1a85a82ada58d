#pragma once
#include <functional>
#include <string>
#include <vector>

#include <cpm/Participant.hpp>
#include <cpm/ReaderOptions.hpp>
#include <cpm/detail/AsyncWorker.hpp>
#include <cpm/detail/ReaderCore.hpp>

namespace cpm {

/// Calls back with every batch of newly arrived samples, in arrival order.
///
/// The callback runs on a thread this reader owns (never a DDS thread, no DDS lock held),
/// one batch at a time. An exception from the callback is logged and reading goes on.
/// stop() and the destructor wake the thread and join it once a running callback returns.
/// Not movable: DDS's receive thread (and the reader's own thread) calls into this very object from the moment it is
/// made. To move one, hold it in a std::unique_ptr.
template <class T>
class AsyncReader
{
public:
    AsyncReader(AsyncReader&&) = delete;
    AsyncReader& operator=(AsyncReader&&) = delete;

    using Callback = std::function<void(std::vector<T>&)>;

    AsyncReader(Callback callback, const std::string& topic, ReaderOptions options = {})
        : AsyncReader(std::move(callback), Participant::default_participant(), topic, options)
    {
    }
    AsyncReader(Callback callback, Participant& participant, const std::string& topic,
                ReaderOptions options = {})
        : core_(participant.core(), topic, &detail::make_type_support<T>, options, "AsyncReader"),
          worker_(core_, [this, callback = std::move(callback)] {
              std::vector<T> batch;
              core_.drain([&](void* s) { batch.push_back(std::move(*static_cast<T*>(s))); });
              if (!batch.empty()) callback(batch);
          })
    {
    }

    /// Stops calling back; returns after a running callback has returned. Idempotent.
    void stop() { worker_.stop(); }

    size_t matched_publications() const { return core_.matched_publications(); }
    [[nodiscard]] bool wait_for_matched(size_t n, std::chrono::milliseconds timeout) const
    {
        return core_.wait_for_matched(n, timeout);
    }

private:
    detail::ReaderCore core_;
    detail::AsyncWorker worker_;  // after core_: joined before the reader goes
};

}  // namespace cpm
