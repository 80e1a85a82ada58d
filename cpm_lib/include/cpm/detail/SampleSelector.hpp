#pragma once
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <vector>

namespace cpm::detail {

/// The buffer behind Reader<T>::get_sample, type-erased. Thread-safe.
///
/// select(t_now) picks, among buffered samples with valid_after <= t_now, the one with the
/// largest create stamp (a tie goes to the later arrival); then drops every other sample
/// that can never win again (create stamp not larger than the pick). With nothing valid it
/// returns no sample and drops nothing. At capacity, the earliest arrival is dropped.
/// add and select are O(buffered samples) at worst, usually O(1) amortised. The samples wait in
/// a ring that grows by doubling up to the capacity, or holds all of it from construction
/// (preallocated: a program in real time, whose loops must not allocate); select compacts it in
/// place and allocates nothing.
class SampleSelector
{
public:
    struct Pick
    {
        std::shared_ptr<const void> sample;  ///< null when no sample is valid at t_now
        uint64_t valid_after_ns = 0;
    };

    /// Preallocated when the program runs with --realtime (cpm::init_settings()).
    explicit SampleSelector(size_t capacity);
    SampleSelector(size_t capacity, bool preallocate);

    void add(uint64_t create_ns, uint64_t valid_after_ns, std::shared_ptr<const void> sample);
    Pick select(uint64_t t_now_ns);
    size_t size() const;
    /// Slots the ring holds now (at most the capacity).
    size_t slots() const;
    /// Samples dropped because the buffer was full.
    uint64_t overflow_count() const;
    /// Waits until a sample is added after the last call returned true (or, the first time,
    /// after construction), or the timeout; true when one was.
    bool wait_for_arrival(std::chrono::nanoseconds timeout);

private:
    struct Entry
    {
        uint64_t create_ns;
        uint64_t valid_after_ns;
        std::shared_ptr<const void> sample;
    };
    Entry& slot(size_t i) { return ring_[(head_ + i) % ring_.size()]; }
    void grow();

    mutable std::mutex mutex_;
    std::vector<Entry> ring_;  // count_ entries from head_ on, in arrival order
    size_t head_ = 0, count_ = 0;
    size_t capacity_;
    uint64_t overflow_count_ = 0;
    uint64_t arrivals_ = 0, arrivals_seen_ = 0;
    std::condition_variable arrived_;
};

}  // namespace cpm::detail
