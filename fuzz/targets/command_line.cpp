// Times, durations and numbers on the command line (cpm history --time, --duration, …): each
// either reads or throws UsageError quoting the flag and the text.
#include "../Fuzz.hpp"

#include <cpm/CommandLine.hpp>

#include <cmath>

CPM_FUZZ_TARGET(command_line)
{
    const std::string text = cpm::fuzz::text(data, size);
    auto quotes = [&](const cpm::cli::UsageError& e) {
        cpm::fuzz::expect(std::string(e.what()).find("--flag") != std::string::npos, "a usage error that does not name the flag");
    };
    try {
        (void)cpm::cli::parse_duration("--flag", text);
    } catch (const cpm::cli::UsageError& e) {
        quotes(e);
    }
    try {
        const uint64_t t = cpm::cli::parse_time("--flag", text, 1'795'446'323'725'000'000ull);
        // What format_time writes, parse_time reads back to the same nanosecond.
        cpm::fuzz::expect(t == 0 || cpm::cli::parse_time("--again", cpm::cli::format_time(t, 9), 0) == t,
                          "parse_time(format_time(t)) != t");
    } catch (const cpm::cli::UsageError& e) {
        quotes(e);
    }
    try {
        const double v = cpm::cli::parse_number("--flag", text, -1e6, 1e6);
        cpm::fuzz::expect(std::isfinite(v) && v >= -1e6 && v <= 1e6, "parse_number let a value outside its range through");
    } catch (const cpm::cli::UsageError& e) {
        quotes(e);
    }
    return 0;
}
