#pragma once
#include <chrono>
#include <cstddef>
#include <functional>
#include <memory>
#include <string>

#include <cpm/ReaderOptions.hpp>
#include <cpm/detail/TypeSupport.hpp>

namespace cpm::detail {
class ParticipantCore;

/// The type-independent part of every reader: one DDS DataReader, its match count, and
/// taking samples out of DDS. Templates (Reader<T>, ...) are thin glue over it.
class ReaderCore
{
public:
    /// Receives one sample with valid data; it may move from it.
    using Sink = std::function<void(void* sample)>;

    /// Runs after a batch of arrivals has been passed to `on_arrival`, on the same thread.
    using BatchEnd = std::function<void()>;

    /// `on_arrival`, if given, is called for every sample as it arrives, on a DDS receive
    /// thread with DDS locks held (used to fill internal buffers; then do not call drain);
    /// `after_arrivals`, if given, after each batch of them (an exception from it is logged).
    /// `role` names the reader in error messages. Only a core with `after_arrivals` (a
    /// callback on the DDS thread) accepts options.dds_thread_callback.
    /// Throws cpm::Error naming the topic when the reader cannot be created.
    ReaderCore(std::shared_ptr<ParticipantCore> participant, const std::string& topic,
               MakeTypeSupport make_type, const ReaderOptions& options, const char* role,
               Sink on_arrival = {}, BatchEnd after_arrivals = {});
    ~ReaderCore();
    ReaderCore(const ReaderCore&) = delete;
    ReaderCore& operator=(const ReaderCore&) = delete;
    /// The DDS reader and the sink move along; the moved-from core may only be destroyed or
    /// assigned to. (A sink that points into its owner makes the owner unmovable.)
    ReaderCore(ReaderCore&& other) noexcept;
    ReaderCore& operator=(ReaderCore&& other) noexcept;

    /// Takes every sample DDS holds and passes each valid one to `sink`, in arrival order.
    /// Returns how many were passed. Never throws.
    size_t drain(const Sink& sink);
    /// Waits until samples are ready to take, `interrupt()` is called, or the timeout.
    /// Returns true when samples are ready.
    bool wait_for_data(std::chrono::nanoseconds timeout);
    /// Wakes every wait_for_data (used to stop worker threads).
    void interrupt();
    /// No more calls of on_arrival/after_arrivals; returns once a running one has returned,
    /// or at once when called from inside one. Idempotent.
    void stop_arrivals();

    size_t matched_publications() const;
    bool wait_for_matched(size_t n, std::chrono::nanoseconds timeout) const;
    const std::string& topic() const;

private:
    void close() noexcept;
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm::detail
