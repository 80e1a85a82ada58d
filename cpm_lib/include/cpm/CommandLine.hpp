#pragma once
#include <cpm/Error.hpp>

#include <cstdint>
#include <cstdio>
#include <functional>
#include <map>
#include <string>
#include <vector>

/// Command-line parsing shared by cpm's programs (`cpm`, `firmware_sim`, `vehicle_bridge`, …):
/// `--name value`, `--name=value` and switches; cpm::init's own flags are passed over.
namespace cpm::cli {

/// A wrong flag or value; programs print it and exit with kUsageExit.
class UsageError : public Error
{
public:
    using Error::Error;
};

constexpr int kUsageExit = 2;

struct FlagSpec
{
    const char* name;
    bool takes_value;  ///< else a switch: present or not
    bool repeatable = false;  ///< may be given more than once (values joined with '\n')
};

struct ParsedArgs
{
    std::map<std::string, std::string> flags;  ///< switches map to "1"
    std::vector<std::string> positional;
    std::vector<std::string> init_args;  ///< cpm::init's flags as given (to pass on to child processes)

    bool has(const std::string& name) const { return flags.count(name) != 0; }
    /// The flag's value, or fallback when absent.
    std::string get(const std::string& name, const std::string& fallback = {}) const;
    /// Every value of a repeatable flag, in the order given (none when absent).
    std::vector<std::string> all(const std::string& name) const;
};

/// Parses `args` against the known flags; throws UsageError naming `command` and the flag.
ParsedArgs parse_args(const std::vector<std::string>& args, const std::vector<FlagSpec>& known,
                      const std::string& command);
/// As parse_args, for a command that takes flags only: an argument that is not a flag is a
/// UsageError naming it.
ParsedArgs parse_flags(const std::vector<std::string>& args, const std::vector<FlagSpec>& known, const std::string& command);
/// A program's flags (argv[1..]), flags only.
ParsedArgs parse_flags(int argc, char** argv, const std::vector<FlagSpec>& known, const std::string& command);

/// True when --help or -h is among the arguments.
bool wants_help(const std::vector<std::string>& args);

/// "500ms", "10s", "2m", "100ns", "20us", "1.5s" → nanoseconds; throws UsageError naming the
/// flag and the text as given when it is not one, is negative or does not fit in 64 bits.
uint64_t parse_duration(const std::string& flag, const std::string& text);
/// A size in bytes: a number with B, kB, MB, GB, TB (powers of 1000) or KiB, MiB, GiB, TiB
/// (of 1024), or none (bytes), e.g. 500MB; throws UsageError naming the flag.
uint64_t parse_bytes(const std::string& flag, const std::string& text);
/// Whether a value reads as a size (ends in B, or a plain number) rather than a duration.
bool looks_like_bytes(const std::string& text);

/// A point in time as nanoseconds since the Unix epoch, from
/// - nanoseconds: `1795446323725000000` (at most 2^64 - 1);
/// - ISO-8601 with a date and a time, in UTC (`2026-11-23T14:05:00.25Z`, or no zone) or with an
///   offset (`2026-11-23T16:05:00+02:00`, `-0500`); the date must exist (no 30 February);
/// - relative to `now_ns`: `now`, `-2s`, `+500ms`.
/// Throws UsageError quoting the flag and the text as given for anything else, and for a time
/// before 1970 (which nanoseconds since the epoch cannot hold).
uint64_t parse_time(const std::string& flag, const std::string& text, uint64_t now_ns);

/// A time for people, as parse_time reads it back: ISO-8601 in UTC with `decimals` (0..9)
/// digits of the second, "2026-11-23T14:05:00.250Z"; "-" for 0 (none).
std::string format_time(uint64_t ns, int decimals = 3);

/// A number within [min, max]; throws UsageError naming the flag and the value.
double parse_number(const std::string& flag, const std::string& text, double min, double max);

/// A whole number within [min, max]; throws UsageError naming the flag and the value.
long long parse_integer(const std::string& flag, const std::string& text, long long min, long long max);

/// "a,b,c" → {"a", "b", "c"}; an empty item is an error.
std::vector<std::string> split_list(const std::string& flag, const std::string& text);

/// A topic pattern as people write it (`*` any text, `?` one character, all else literal) as
/// the full-match ECMAScript regex the history service takes: "vehicle*" → "vehicle.*".
std::string glob_regex(const std::string& glob);

/// From now on SIGINT and SIGTERM only set the flag stop_requested() reads (the program then
/// ends its loop and cleans up: DDS shared memory is only freed by a normal exit).
void stop_on_signals();
/// True once SIGINT or SIGTERM arrived after stop_on_signals(). Async-signal-safe to set.
bool stop_requested();

/// A program's main: prints `help` for --help/-h (exit 0), else returns run(argc, argv); a
/// UsageError is printed as "program: message" with exit code kUsageExit, any other exception
/// with exit code 1.
int run_main(int argc, char** argv, const char* program, const char* help,
             const std::function<int(int, char**)>& run);

/// A node program's life after its setup: runs `node.run(stop_requested)` until SIGINT or
/// SIGTERM (or the node ends by itself), then prints `node.stats_json()` as one line on stdout.
template <class Node>
int run_node(Node& node)
{
    stop_on_signals();
    node.run(stop_requested);
    std::printf("%s\n", node.stats_json().c_str());
    std::fflush(stdout);
    return 0;
}

}  // namespace cpm::cli
