// cpm_fuzz_replay TARGET PATH...: runs every file under each PATH (a file or a folder) through the
// fuzz target, as the fuzzer would; the checked-in corpus replayed as a test in every build.
// Prints how many inputs ran and the slowest; a finding aborts (the test fails).
#include "Fuzz.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

namespace fs = std::filesystem;

int main(int argc, char** argv)
{
    const auto& all = cpm::fuzz::targets();
    auto usage = [&] {
        std::fprintf(stderr, "usage: cpm_fuzz_replay TARGET PATH...\ntargets:");
        for (const auto& [name, t] : all) std::fprintf(stderr, " %s", name.c_str());
        std::fprintf(stderr, "\n");
        return 2;
    };
    if (argc < 3) return usage();
    const std::string name = argv[1];
    auto it = std::find_if(all.begin(), all.end(), [&](const auto& e) { return e.first == name; });
    if (it == all.end()) {
        std::fprintf(stderr, "cpm_fuzz_replay: no target '%s'\n", name.c_str());
        return usage();
    }
    std::vector<fs::path> files;
    for (int i = 2; i < argc; ++i) {
        const fs::path p = argv[i];
        if (fs::is_directory(p)) {
            for (const auto& e : fs::recursive_directory_iterator(p))
                if (e.is_regular_file()) files.push_back(e.path());
        } else if (fs::is_regular_file(p)) {
            files.push_back(p);
        } else {
            std::fprintf(stderr, "cpm_fuzz_replay: %s: no such file or folder\n", p.c_str());
            return 2;
        }
    }
    if (files.empty()) {
        std::fprintf(stderr, "cpm_fuzz_replay: no inputs under the paths given\n");
        return 2;
    }
    std::sort(files.begin(), files.end());
    double slowest = 0;
    fs::path slowest_file;
    for (const auto& f : files) {
        std::ifstream in(f, std::ios::binary);
        const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        const auto t0 = std::chrono::steady_clock::now();
        it->second(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size());
        const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        if (s > slowest) slowest = s, slowest_file = f;
    }
    std::printf("%s: %zu inputs, slowest %.3f s (%s)\n", name.c_str(), files.size(), slowest, slowest_file.filename().c_str());
    return 0;
}
