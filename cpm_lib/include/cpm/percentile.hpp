#pragma once
#include <algorithm>
#include <cstddef>
#include <vector>

namespace cpm {

/// The p-quantile (0 ≤ p ≤ 1) of `values` by the nearest-rank rule (the element at rank
/// floor(p·n), the largest for p = 1); T() for no values. Takes a copy: O(n).
template <class T>
T percentile(std::vector<T> values, double p)
{
    if (values.empty()) return T();
    const size_t k = std::min(values.size() - 1, size_t(std::max(0.0, p) * double(values.size())));
    std::nth_element(values.begin(), values.begin() + std::ptrdiff_t(k), values.end());
    return values[k];
}

}  // namespace cpm
