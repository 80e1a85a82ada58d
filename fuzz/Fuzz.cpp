#include "Fuzz.hpp"

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <unistd.h>

namespace cpm::fuzz {

namespace {

std::vector<std::pair<std::string, Target>>& registry()
{
    static std::vector<std::pair<std::string, Target>> all;
    return all;
}

struct ScratchDir
{
    std::filesystem::path path;
    ScratchDir()
    {
        // Memory rather than disk when there is a tmpfs: the file parsers' targets run twice as fast.
        const char* tmp = std::getenv("TMPDIR");
        const std::filesystem::path base = tmp && *tmp ? tmp : ::access("/dev/shm", W_OK) == 0 ? "/dev/shm" : "/tmp";
        path = base / ("cpm_fuzz_" + std::to_string(::getpid()));
        std::filesystem::create_directories(path);
    }
    ~ScratchDir()
    {
        std::error_code ignored;
        std::filesystem::remove_all(path, ignored);
    }
};

}  // namespace

bool add_target(const char* name, Target target)
{
    registry().emplace_back(name, target);
    return true;
}

const std::vector<std::pair<std::string, Target>>& targets() { return registry(); }

std::string scratch_file(const std::string& name, const uint8_t* data, size_t size)
{
    static ScratchDir dir;
    const auto file = dir.path / name;
    std::ofstream(file, std::ios::binary | std::ios::trunc).write(reinterpret_cast<const char*>(data), std::streamsize(size));
    return file.string();
}

void expect(bool ok, const char* what)
{
    if (ok) return;
    std::fprintf(stderr, "fuzz finding: %s\n", what);
    std::abort();
}

}  // namespace cpm::fuzz
