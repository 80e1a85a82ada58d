#include "ObjectState.hpp"

namespace cpm::rtdb::detail {

uint64_t ObjectState::lost_before(uint64_t commit) const
{
    auto it = std::lower_bound(gaps.begin(), gaps.end(), std::make_pair(commit, uint64_t(0)));
    return it != gaps.end() && it->first == commit ? it->second : 0;
}

uint64_t ObjectState::lost_within(uint64_t from, uint64_t to) const
{
    uint64_t n = 0;
    for (const auto& [c, k] : gaps) n += c > from && c <= to ? k : 0;
    return n;
}

ObjectInfo ObjectState::described() const
{
    ObjectInfo i = info;
    i.samples_held = records.size();
    i.bytes_held = bytes_held;
    i.samples_total = samples_total;
    i.samples_lost = lost_total;
    i.newest_commit_ns = records.empty() ? 0 : records.back().commit;
    i.oldest_commit_ns = records.empty() ? 0 : records.front().commit;
    i.avg_cycle_s = samples_total > 1 ? double(cycle_sum) * 1e-9 / double(samples_total - 1) : 0;
    i.max_cycle_s = double(cycle_max) * 1e-9;
    return i;
}

}  // namespace cpm::rtdb::detail
