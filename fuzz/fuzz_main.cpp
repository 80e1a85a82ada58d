// libFuzzer's entry points for cpm_fuzz, the fuzzing build's one executable: CPM_FUZZ_TARGET
// names the target to fuzz (./lab fuzz sets it).
#include "Fuzz.hpp"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace {
cpm::fuzz::Target chosen = nullptr;
}

extern "C" int LLVMFuzzerInitialize(int*, char***)
{
    const auto& all = cpm::fuzz::targets();
    const char* name = std::getenv("CPM_FUZZ_TARGET");
    auto it = std::find_if(all.begin(), all.end(), [&](const auto& e) { return name && e.first == name; });
    if (it == all.end()) {
        std::fprintf(stderr, "cpm_fuzz: set CPM_FUZZ_TARGET to one of:");
        for (const auto& [n, t] : all) std::fprintf(stderr, " %s", n.c_str());
        std::fprintf(stderr, "\n");
        std::exit(2);
    }
    chosen = it->second;
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) { return chosen(data, size); }
