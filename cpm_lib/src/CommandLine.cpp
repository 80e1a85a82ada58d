#include <cpm/CommandLine.hpp>
#include <cpm/init.hpp>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <ctime>
#include <map>
#include <optional>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <sstream>

namespace cpm::cli {

std::string ParsedArgs::get(const std::string& name, const std::string& fallback) const
{
    auto it = flags.find(name);
    return it == flags.end() ? fallback : it->second;
}

std::vector<std::string> ParsedArgs::all(const std::string& name) const
{
    std::vector<std::string> values;
    auto it = flags.find(name);
    if (it == flags.end()) return values;
    std::istringstream joined(it->second);
    for (std::string v; std::getline(joined, v);) values.push_back(v);
    return values;
}

ParsedArgs parse_args(const std::vector<std::string>& args, const std::vector<FlagSpec>& known,
                      const std::string& command)
{
    ParsedArgs parsed;
    for (size_t i = 0; i < args.size(); ++i) {
        std::string name = args[i], value;
        if (name.rfind("--", 0) != 0) {
            parsed.positional.push_back(name);
            continue;
        }
        const auto eq = name.find('=');
        if (eq != std::string::npos) {
            value = name.substr(eq + 1);
            name = name.substr(0, eq);
        }
        bool takes_value = false;
        if (is_init_flag(name, takes_value)) {
            parsed.init_args.push_back(args[i]);
            if (takes_value && eq == std::string::npos && i + 1 < args.size()) parsed.init_args.push_back(args[++i]);
            continue;
        }
        const FlagSpec* spec = nullptr;
        for (const auto& k : known) {
            if (name == k.name) spec = &k;
        }
        if (spec == nullptr) throw UsageError(command + ": unknown flag '" + name + "' (see --help)");
        if (!spec->takes_value) {
            if (eq != std::string::npos)
                throw UsageError(command + ": " + name + " is a switch and takes no value ('" + args[i] + "'): give " + name + ", or leave it out");
            parsed.flags[name] = "1";
            continue;
        }
        if (eq == std::string::npos) {
            // `--topic --key 1`: the next word is a flag, not the value --topic needs.
            if (i + 1 >= args.size() || args[i + 1].rfind("--", 0) == 0)
                throw UsageError(command + ": " + name + " needs a value");
            value = args[++i];
        }
        auto [it, inserted] = parsed.flags.emplace(name, value);
        if (!inserted) {
            if (!spec->repeatable) throw UsageError(command + ": " + name + " given twice");
            it->second += "\n" + value;
        }
    }
    return parsed;
}

bool wants_help(const std::vector<std::string>& args)
{
    for (const auto& a : args) {
        if (a == "--help" || a == "-h") return true;
    }
    return false;
}

namespace {

/// A non-negative number followed by one of `units` (name → multiplier), below 2^64 once
/// multiplied; none when the text is not one.
std::optional<uint64_t> number_with_unit(const std::string& text, const std::map<std::string, uint64_t>& units)
{
    size_t end = 0;
    double value = 0;
    try {
        value = std::stod(text, &end);
    } catch (const std::exception&) {
        end = 0;
    }
    const auto unit = units.find(text.substr(end));
    if (end == 0 || unit == units.end() || !(value >= 0) || !std::isdigit(static_cast<unsigned char>(text[0])) ||
        !(value * double(unit->second) < 18446744073709551615.0)) {
        return std::nullopt;
    }
    return static_cast<uint64_t>(value * double(unit->second));
}

}  // namespace

uint64_t parse_duration(const std::string& flag, const std::string& text)
{
    static const std::map<std::string, uint64_t> units{{"ns", 1},          {"us", 1'000},       {"ms", 1'000'000},          {"s", 1'000'000'000},
                                                       {"m", 60'000'000'000}, {"min", 60'000'000'000}, {"h", 3'600'000'000'000}};
    const auto v = number_with_unit(text, units);
    if (!v) throw UsageError(flag + ": '" + text + "' is not a duration (a number of at most 2^64 ns with ns, us, ms, s, m or h, e.g. 10s)");
    return *v;
}

uint64_t parse_bytes(const std::string& flag, const std::string& text)
{
    static const std::map<std::string, uint64_t> units{{"", 1},
                                                       {"B", 1},
                                                       {"kB", 1'000},
                                                       {"KB", 1'000},
                                                       {"MB", 1'000'000},
                                                       {"GB", 1'000'000'000},
                                                       {"TB", 1'000'000'000'000},
                                                       {"KiB", 1ull << 10},
                                                       {"MiB", 1ull << 20},
                                                       {"GiB", 1ull << 30},
                                                       {"TiB", 1ull << 40}};
    const auto v = number_with_unit(text, units);
    if (!v) throw UsageError(flag + ": '" + text + "' is not a size (a number with B, kB, MB, GB, TB, KiB, MiB, GiB or TiB, e.g. 500MB)");
    return *v;
}

bool looks_like_bytes(const std::string& text)
{
    return !text.empty() && (text.back() == 'B' || text.find_first_not_of("0123456789.") == std::string::npos);
}

ParsedArgs parse_flags(const std::vector<std::string>& args, const std::vector<FlagSpec>& known, const std::string& command)
{
    ParsedArgs parsed = parse_args(args, known, command);
    if (!parsed.positional.empty()) throw UsageError(command + ": unexpected argument '" + parsed.positional[0] + "'");
    return parsed;
}

ParsedArgs parse_flags(int argc, char** argv, const std::vector<FlagSpec>& known, const std::string& command)
{
    return parse_flags(std::vector<std::string>(argv + 1, argv + argc), known, command);
}

std::string format_time(uint64_t ns, int decimals)
{
    if (!ns) return "-";
    decimals = std::clamp(decimals, 0, 9);
    const std::time_t secs = std::time_t(ns / 1'000'000'000ull);
    std::tm tm{};
    ::gmtime_r(&secs, &tm);
    char buf[48];
    std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%S", &tm);
    char frac[16];
    std::snprintf(frac, sizeof frac, "%09llu", (unsigned long long)(ns % 1'000'000'000ull));
    return std::string(buf) + (decimals ? "." + std::string(frac, size_t(decimals)) : "") + "Z";
}

uint64_t parse_time(const std::string& flag, const std::string& text, uint64_t now_ns)
{
    const std::string kinds = "nanoseconds, ISO-8601 (2026-11-23T14:05:00.25Z, +02:00 offsets too) or relative (-2s, now)";
    auto fail = [&](const std::string& why) { return UsageError(flag + ": '" + text + "' " + why); };
    if (text == "now") return now_ns;
    if (!text.empty() && (text[0] == '-' || text[0] == '+')) {
        uint64_t d = 0;
        try {
            d = parse_duration(flag, text.substr(1));
        } catch (const UsageError&) {
            throw fail("is not a relative time (a sign and a duration with its unit: -2s, +500ms)");
        }
        if (text[0] == '-' && d > now_ns) throw fail("lies before 1970, which nanoseconds since the epoch cannot hold");
        if (text[0] == '+' && d > UINT64_MAX - now_ns) throw fail("lies beyond what 64-bit nanoseconds can hold");
        return text[0] == '-' ? now_ns - d : now_ns + d;
    }
    if (!text.empty() && text.find_first_not_of("0123456789") == std::string::npos) {
        errno = 0;
        const unsigned long long v = std::strtoull(text.c_str(), nullptr, 10);
        if (errno == ERANGE) throw fail("is more nanoseconds than 64 bits hold (at most 18446744073709551615)");
        return v;
    }
    std::tm tm{};
    const char* rest = ::strptime(text.c_str(), "%Y-%m-%dT%H:%M:%S", &tm);
    if (rest == nullptr) throw fail("is not a time: expected " + kinds);
    const std::tm asked = tm;
    uint64_t frac_ns = 0;
    if (*rest == '.') {
        ++rest;
        uint64_t scale = 100'000'000;
        if (!std::isdigit(static_cast<unsigned char>(*rest))) throw fail("has no digits after its decimal point");
        while (std::isdigit(static_cast<unsigned char>(*rest))) {
            frac_ns += uint64_t(*rest - '0') * scale;
            scale /= 10;
            ++rest;
        }
    }
    long long offset_s = 0;
    if (*rest == 'Z') {
        ++rest;
    } else if (*rest == '+' || *rest == '-') {
        const int sign = *rest == '-' ? -1 : 1;
        int hh = 0, mm = 0, used = 0;
        if (std::sscanf(rest + 1, "%2d:%2d%n", &hh, &mm, &used) != 2 || used != 5) {
            used = 0;
            if (std::sscanf(rest + 1, "%2d%2d%n", &hh, &mm, &used) != 2 || used != 4)
                throw fail("has a zone offset that is not +HH:MM or +HHMM");
        }
        if (hh > 23 || mm > 59) throw fail("has a zone offset beyond 23:59");
        offset_s = sign * (hh * 3600LL + mm * 60LL);
        rest += 1 + used;
    }
    if (*rest != '\0') throw fail("has '" + std::string(rest) + "' after the time: expected " + kinds);
    const long long utc = static_cast<long long>(::timegm(&tm));
    // timegm normalises 30 February into 2 March: a date that does not exist comes back changed.
    if (tm.tm_mday != asked.tm_mday || tm.tm_mon != asked.tm_mon || tm.tm_hour != asked.tm_hour ||
        tm.tm_min != asked.tm_min || tm.tm_sec != asked.tm_sec) {
        throw fail("is not a date and time that exists");
    }
    const long long seconds = utc - offset_s;
    if (seconds < 0) throw fail("lies before 1970, which nanoseconds since the epoch cannot hold");
    if (seconds > 18'446'744'072LL) throw fail("lies beyond what 64-bit nanoseconds can hold (2554)");
    return uint64_t(seconds) * 1'000'000'000ull + frac_ns;
}

double parse_number(const std::string& flag, const std::string& text, double min, double max)
{
    size_t end = 0;
    double value = NAN;
    try {
        value = std::stod(text, &end);
    } catch (const std::exception&) {
        end = 0;
    }
    if (end == 0 || end != text.size() || !(value >= min && value <= max)) {
        std::ostringstream range;
        range << min << ".." << max;
        throw UsageError(flag + ": '" + text + "' is not a number in " + range.str());
    }
    return value;
}

long long parse_integer(const std::string& flag, const std::string& text, long long min, long long max)
{
    size_t end = 0;
    long long value = 0;
    try {
        value = std::stoll(text, &end);
    } catch (const std::exception&) {
        end = 0;
    }
    if (end == 0 || end != text.size() || value < min || value > max) {
        throw UsageError(flag + ": '" + text + "' is not a whole number in " + std::to_string(min) + ".." +
                         std::to_string(max));
    }
    return value;
}

std::vector<std::string> split_list(const std::string& flag, const std::string& text)
{
    std::vector<std::string> items;
    std::stringstream in(text);
    for (std::string item; std::getline(in, item, ',');) {
        if (item.empty()) throw UsageError(flag + ": empty item in '" + text + "'");
        items.push_back(item);
    }
    if (items.empty()) throw UsageError(flag + ": nothing given");
    return items;
}

std::string glob_regex(const std::string& glob)
{
    std::string re;
    for (char c : glob) {
        if (c == '*') re += ".*";
        else if (c == '?') re += '.';
        else if (std::strchr("\\^$.|+()[]{}", c)) re += std::string("\\") + c;
        else re += c;
    }
    return re;
}

namespace {
// Set by the signal handler, read by any thread (a timer's, a node's loop): a lock-free atomic,
// which is safe in a handler, not a volatile sig_atomic_t, which is safe only for the thread
// the signal interrupted (TSan reported the timer thread's read as a race).
std::atomic<bool> g_stop_requested{false};
static_assert(std::atomic<bool>::is_always_lock_free);
}  // namespace

void stop_on_signals()
{
    std::signal(SIGINT, [](int) { g_stop_requested.store(true); });
    std::signal(SIGTERM, [](int) { g_stop_requested.store(true); });
}

bool stop_requested() { return g_stop_requested.load(); }

int run_main(int argc, char** argv, const char* program, const char* help, const std::function<int(int, char**)>& run)
{
    if (wants_help(std::vector<std::string>(argv + 1, argv + argc))) {
        std::fputs(help, stdout);
        return 0;
    }
    // The program's name once, whether or not the message already starts with it.
    auto report = [program](const char* what) {
        const std::string prefix = std::string(program) + ": ";
        std::fprintf(stderr, "%s%s\n", std::string(what).rfind(prefix, 0) == 0 ? "" : prefix.c_str(), what);
    };
    try {
        return run(argc, argv);
    } catch (const UsageError& e) {
        report(e.what());
        return kUsageExit;
    } catch (const std::exception& e) {
        report(e.what());
        return 1;
    }
}

}  // namespace cpm::cli
