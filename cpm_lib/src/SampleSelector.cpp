#include <cpm/detail/SampleSelector.hpp>

#include <algorithm>

namespace cpm::detail {

SampleSelector::SampleSelector(size_t capacity) : capacity_(std::max<size_t>(capacity, 1)) {}

void SampleSelector::add(uint64_t create_ns, uint64_t valid_after_ns, std::shared_ptr<const void> sample)
{
    std::lock_guard<std::mutex> lock(mutex_);
    if (entries_.size() >= capacity_) {
        entries_.pop_front();
        ++overflow_count_;
    }
    entries_.push_back(Entry{create_ns, valid_after_ns, std::move(sample)});
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
    auto best = entries_.end();
    for (auto it = entries_.begin(); it != entries_.end(); ++it) {
        if (it->valid_after_ns <= t_now_ns && (best == entries_.end() || it->create_ns >= best->create_ns)) {
            best = it;
        }
    }
    if (best == entries_.end()) return {};

    Pick pick{best->sample, best->valid_after_ns};
    const uint64_t chosen_create = best->create_ns;
    const auto chosen_position = best - entries_.begin();
    // Keep the pick and what may still beat it: a larger create stamp, or an equal one
    // that arrived later.
    std::deque<Entry> kept;
    for (auto it = entries_.begin(); it != entries_.end(); ++it) {
        const bool later = (it - entries_.begin()) >= chosen_position;
        if (it->create_ns > chosen_create || (it->create_ns == chosen_create && later)) {
            kept.push_back(std::move(*it));
        }
    }
    entries_.swap(kept);
    return pick;
}

size_t SampleSelector::size() const
{
    std::lock_guard<std::mutex> lock(mutex_);
    return entries_.size();
}

uint64_t SampleSelector::overflow_count() const
{
    std::lock_guard<std::mutex> lock(mutex_);
    return overflow_count_;
}

}  // namespace cpm::detail
