#include <cpm/detail/SampleSelector.hpp>

#include <cpm/init.hpp>

#include <algorithm>

namespace cpm::detail {

SampleSelector::SampleSelector(size_t capacity) : SampleSelector(capacity, init_settings().realtime != Realtime::off) {}

SampleSelector::SampleSelector(size_t capacity, bool preallocate) : capacity_(std::max<size_t>(capacity, 1))
{
    ring_.resize(preallocate ? capacity_ : std::min<size_t>(capacity_, 8));
}

void SampleSelector::grow()
{
    std::vector<Entry> bigger(std::min(capacity_, ring_.size() * 2));
    for (size_t i = 0; i < count_; ++i) bigger[i] = std::move(slot(i));
    ring_.swap(bigger);
    head_ = 0;
}

void SampleSelector::add(uint64_t create_ns, uint64_t valid_after_ns, std::shared_ptr<const void> sample)
{
    std::lock_guard<std::mutex> lock(mutex_);
    if (count_ >= capacity_) {  // the ring is at its capacity: the earliest arrival goes
        slot(0) = Entry{};
        head_ = (head_ + 1) % ring_.size();
        --count_;
        ++overflow_count_;
    } else if (count_ == ring_.size()) {
        grow();
    }
    slot(count_) = Entry{create_ns, valid_after_ns, std::move(sample)};
    ++count_;
    ++arrivals_;
    arrived_.notify_all();
}

bool SampleSelector::wait_for_arrival(std::chrono::nanoseconds timeout)
{
    std::unique_lock<std::mutex> lock(mutex_);
    if (!arrived_.wait_for(lock, timeout, [&] { return arrivals_ != arrivals_seen_; })) return false;
    arrivals_seen_ = arrivals_;
    return true;
}

SampleSelector::Pick SampleSelector::select(uint64_t t_now_ns)
{
    std::lock_guard<std::mutex> lock(mutex_);
    // Scan in arrival order; `>=` lets a later arrival win a create-stamp tie.
    constexpr size_t none = SIZE_MAX;
    size_t best = none;
    for (size_t i = 0; i < count_; ++i) {
        const Entry& e = slot(i);
        if (e.valid_after_ns <= t_now_ns && (best == none || e.create_ns >= slot(best).create_ns)) best = i;
    }
    if (best == none) return {};

    Pick pick{slot(best).sample, slot(best).valid_after_ns};
    const uint64_t chosen_create = slot(best).create_ns;
    // Keep the pick and what may still beat it - a larger create stamp, or an equal one that
    // arrived later - in their order, compacted towards the head in place.
    size_t kept = 0;
    for (size_t i = 0; i < count_; ++i) {
        Entry& e = slot(i);
        if (e.create_ns > chosen_create || (e.create_ns == chosen_create && i >= best)) {
            if (kept != i) slot(kept) = std::move(e);
            ++kept;
        }
    }
    for (size_t i = kept; i < count_; ++i) slot(i) = Entry{};
    count_ = kept;
    return pick;
}

size_t SampleSelector::size() const
{
    std::lock_guard<std::mutex> lock(mutex_);
    return count_;
}

size_t SampleSelector::slots() const
{
    std::lock_guard<std::mutex> lock(mutex_);
    return ring_.size();
}

uint64_t SampleSelector::overflow_count() const
{
    std::lock_guard<std::mutex> lock(mutex_);
    return overflow_count_;
}

}  // namespace cpm::detail
