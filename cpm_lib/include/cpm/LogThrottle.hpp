#pragma once
#include <cstdint>

namespace cpm {

/// Lets a repeated message through at most once per interval and counts the ones it held back,
/// so that a fault that repeats 50 times a second is logged once a second with a count instead
/// of flooding the log. Not thread-safe: one per message kind, owned by the loop that logs it.
///
///     static cpm::LogThrottle throttle;              // once per second
///     uint64_t held = 0;
///     if (throttle.allow(cpm::get_time_ns(), held))
///         CPM_LOG_WARN("refused a command (%llu more since the last report)", (unsigned long long)held);
class LogThrottle
{
public:
    explicit LogThrottle(uint64_t interval_ns = 1'000'000'000ull) : interval_ns_(interval_ns) {}

    /// True when a message may be written at t_now_ns (the first one always may); `held_back`
    /// is then set to how many calls were refused since the last message that went through.
    bool allow(uint64_t t_now_ns, uint64_t& held_back)
    {
        ++total_;
        if (passed_ && t_now_ns < last_ns_ + interval_ns_) {
            ++held_;
            return false;
        }
        held_back = held_;
        held_ = 0;
        last_ns_ = t_now_ns;
        passed_ = true;
        return true;
    }
    /// Every call to allow() so far, let through or not.
    uint64_t total() const { return total_; }

private:
    uint64_t interval_ns_;
    uint64_t last_ns_ = 0;
    uint64_t held_ = 0;
    uint64_t total_ = 0;
    bool passed_ = false;
};

}  // namespace cpm
