#pragma once
// Command-line flags of the demo programs.
#include <cpm/Error.hpp>

#include <cstdlib>
#include <cstring>
#include <string>

namespace demo {

/// True when --help is among the arguments.
inline bool wants_help(int argc, char** argv)
{
    for (int i = 1; i < argc; ++i) {
        if (std::strcmp(argv[i], "--help") == 0) return true;
    }
    return false;
}

/// The whole number after `name` (e.g. "--vehicles 4"), or fallback when absent.
/// Throws cpm::Error naming the flag and value when it is not a number in [min, max].
inline int int_flag(int argc, char** argv, const char* name, int fallback, int min, int max)
{
    for (int i = 1; i < argc; ++i) {
        if (std::strcmp(argv[i], name) != 0) continue;
        if (i + 1 >= argc) throw cpm::Error(std::string(name) + ": missing value");
        char* end = nullptr;
        const long value = std::strtol(argv[i + 1], &end, 10);
        if (*argv[i + 1] == '\0' || *end != '\0' || value < min || value > max) {
            throw cpm::Error(std::string(name) + ": '" + argv[i + 1] + "' is not a whole number in " +
                             std::to_string(min) + ".." + std::to_string(max));
        }
        return static_cast<int>(value);
    }
    return fallback;
}

}  // namespace demo
