#pragma once
#include <functional>
#include <memory>
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
/// one batch at a time. With options.dds_thread_callback it runs instead on the DDS receive
/// thread that delivered the batch, with the reader's DDS lock held: one thread hop less,
/// for callbacks that are short and never block (see ReaderOptions). An exception from the
/// callback is logged and reading goes on.
/// stop() and the destructor end the callbacks and return once a running callback returns.
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
        : dds_thread_callback_(options.dds_thread_callback ? std::move(callback) : Callback{}),
          core_(participant.core(), topic, &detail::make_type_support<T>, options, "AsyncReader",
                arrival_sink(options), batch_end(options))
    {
        if (options.dds_thread_callback) return;
        // The worker owns what it touches, so a reader destroyed from inside its callback is safe.
        worker_ = std::make_unique<detail::AsyncWorker>(core_, [this, callback = std::move(callback)] {
            std::vector<T> batch;
            core_.drain([&](void* s) { detail::with_lent<T>(s, [&](T& t) { batch.push_back(std::move(t)); }); });
            if (!batch.empty()) callback(batch);
        });
    }

    /// Stops calling back; returns after a running callback has returned (at once when
    /// called from inside the callback). Idempotent.
    void stop()
    {
        if (worker_) worker_->stop();
        else core_.stop_arrivals();
    }

    size_t matched_publications() const { return core_.matched_publications(); }
    [[nodiscard]] bool wait_for_matched(size_t n, std::chrono::milliseconds timeout) const
    {
        return core_.wait_for_matched(n, timeout);
    }

private:
    // On the DDS thread: each sample joins the batch, then the batch is delivered.
    detail::ReaderCore::Sink arrival_sink(const ReaderOptions& options)
    {
        if (!options.dds_thread_callback) return {};
        return [this](void* s) { detail::with_lent<T>(s, [this](T& t) { batch_.push_back(std::move(t)); }); };
    }
    detail::ReaderCore::BatchEnd batch_end(const ReaderOptions& options)
    {
        if (!options.dds_thread_callback) return {};
        return [this] { deliver(); };
    }
    void deliver()
    {
        if (batch_.empty()) return;
        struct Clear  // the batch is emptied even when the callback throws
        {
            std::vector<T>& batch;
            ~Clear() { batch.clear(); }
        } clear{batch_};
        dds_thread_callback_(batch_);
    }

    Callback dds_thread_callback_;
    std::vector<T> batch_;  // the DDS thread's batch, one at a time: its capacity is reused
    detail::ReaderCore core_;
    std::unique_ptr<detail::AsyncWorker> worker_;  // after core_: joined before the reader goes
};

}  // namespace cpm
