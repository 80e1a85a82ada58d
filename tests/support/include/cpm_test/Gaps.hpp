// For a failed rate check to say where the samples went missing.
#pragma once
#include <algorithm>
#include <cstdint>
#include <fstream>
#include <string>
#include <vector>

namespace cpm_test {

/// The gaps longer than `longer_than_ns` between consecutive stamps (sorted here), as
/// "40 ms at +1239 ms, ..." with each gap's start relative to `t0`; "none" when there is none.
inline std::string gaps_over(std::vector<uint64_t> stamps, uint64_t t0, uint64_t longer_than_ns)
{
    std::sort(stamps.begin(), stamps.end());
    std::string out;
    for (size_t k = 1; k < stamps.size(); ++k) {
        const uint64_t gap = stamps[k] - stamps[k - 1];
        if (gap > longer_than_ns)
            out += (out.empty() ? "" : ", ") + std::to_string(gap / 1'000'000) + " ms at +" +
                   std::to_string((stamps[k - 1] - t0) / 1'000'000) + " ms";
    }
    return out.empty() ? "none" : out;
}

/// The warnings and errors a program logged to `path` ("[warn] …", "[error] …" lines), for a
/// failed rate check to say what the car's own programs saw; "" when there are none.
inline std::string warnings_in(const std::string& path)
{
    std::ifstream in(path);
    std::string out;
    for (std::string line; std::getline(in, line);) {
        if (line.rfind("[warn]", 0) == 0 || line.rfind("[error]", 0) == 0) out += "    " + line + "\n";
    }
    return out;
}

}  // namespace cpm_test
