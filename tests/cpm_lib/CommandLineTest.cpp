// cpm::cli, the flag parsing every cpm program shares: values, switches, repeatable flags,
// durations, numbers and lists, and the messages a wrong one gets.
#include <cpm/CommandLine.hpp>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

using ::testing::HasSubstr;
using namespace cpm::cli;

namespace {

template <typename F>
std::string usage_error(F&& f)
{
    try {
        f();
    } catch (const UsageError& e) {
        return e.what();
    }
    return "(no error)";
}

TEST(CommandLine, TakesValuesSwitchesRepeatsAndPositionalsAndNamesAnUnknownFlag)
{
    const std::vector<FlagSpec> known{{"--topic", true}, {"--json", false}, {"--include", true, true}};
    auto p = parse_args({"at", "--topic", "vehicleState", "--json", "--include=a*", "--include", "b*"}, known, "cpm history");
    EXPECT_EQ(p.get("--topic"), "vehicleState");
    EXPECT_TRUE(p.has("--json"));
    EXPECT_EQ(p.all("--include"), (std::vector<std::string>{"a*", "b*"}));
    EXPECT_EQ(p.positional, std::vector<std::string>{"at"});
    EXPECT_EQ(p.get("--missing", "fallback"), "fallback");
    EXPECT_THAT(usage_error([&] { parse_args({"--topik", "x"}, known, "cpm history"); }), HasSubstr("--topik"));
    EXPECT_THAT(usage_error([&] { parse_args({"--topic"}, known, "cpm history"); }), HasSubstr("--topic"));
}

TEST(CommandLine, DurationsFromNanosecondsToHours)
{
    EXPECT_EQ(parse_duration("--t", "250ns"), 250u);
    EXPECT_EQ(parse_duration("--t", "3us"), 3'000u);
    EXPECT_EQ(parse_duration("--t", "500ms"), 500'000'000u);
    EXPECT_EQ(parse_duration("--t", "1.5s"), 1'500'000'000u);
    EXPECT_EQ(parse_duration("--t", "2m"), 120'000'000'000u);
    EXPECT_EQ(parse_duration("--t", "1h"), 3'600'000'000'000u);
    for (const char* bad : {"10", "ten s", "5 parsecs", "-1s", ""}) {
        EXPECT_THAT(usage_error([&] { parse_duration("--window", bad); }), HasSubstr("--window: '" + std::string(bad) + "' is not a duration"))
            << bad;
    }
}

TEST(CommandLine, NumbersIntegersAndListsAreCheckedAgainstTheirRange)
{
    EXPECT_EQ(parse_number("--gain", "0.25", 0, 1), 0.25);
    EXPECT_EQ(parse_integer("--id", "7", 1, 255), 7);
    EXPECT_EQ(split_list("--objects", "a,b/2"), (std::vector<std::string>{"a", "b/2"}));
    EXPECT_THAT(usage_error([] { parse_number("--gain", "2", 0, 1); }), HasSubstr("--gain"));
    EXPECT_THAT(usage_error([] { parse_integer("--id", "256", 1, 255); }), HasSubstr("--id"));
    EXPECT_THAT(usage_error([] { parse_integer("--id", "7x", 1, 255); }), HasSubstr("7x"));
}

}  // namespace

TEST(CommandLine, TimesAreNanosecondsIsoWithOffsetsOrRelative)
{
    const uint64_t now = 1'795'446'323'725'000'000ull;
    EXPECT_EQ(parse_time("--time", "1795446323725000000", now), 1'795'446'323'725'000'000ull);
    EXPECT_EQ(parse_time("--time", "18446744073709551615", now), UINT64_MAX);
    EXPECT_EQ(parse_time("--time", "now", now), now);
    EXPECT_EQ(parse_time("--time", "-2s", now), now - 2'000'000'000ull);
    EXPECT_EQ(parse_time("--time", "+500ms", now), now + 500'000'000ull);
    EXPECT_EQ(parse_time("--time", "1970-01-01T00:00:00Z", now), 0u);
    EXPECT_EQ(parse_time("--time", "2026-11-23T14:05:00.25Z", now), 1'795'442'700'250'000'000ull);
    EXPECT_EQ(parse_time("--time", "2026-11-23T14:05:00.25", now), 1'795'442'700'250'000'000ull);
    EXPECT_EQ(parse_time("--time", "2026-11-23T16:05:00.25+02:00", now), 1'795'442'700'250'000'000ull);
    EXPECT_EQ(parse_time("--time", "2026-11-23T09:05:00.25-0500", now), 1'795'442'700'250'000'000ull);
    EXPECT_EQ(parse_time("--time", "2024-02-29T00:00:00Z", now), 1'709'164'800'000'000'000ull);  // a leap day
}

TEST(CommandLine, WhatIsNotATimeIsRefusedQuotingTheArgumentAsGiven)
{
    const uint64_t now = 1'795'446'323'725'000'000ull;
    auto error = [&](const std::string& text) { return usage_error([&] { parse_time("--time", text, now); }); };
    EXPECT_THAT(error("1969-12-31T23:59:59Z"), HasSubstr("--time: '1969-12-31T23:59:59Z' lies before 1970"));
    EXPECT_THAT(error("18446744073709551616"), HasSubstr("--time: '18446744073709551616' is more nanoseconds than 64 bits hold"));
    EXPECT_THAT(error("99999999999999999999999"), HasSubstr("more nanoseconds than 64 bits hold"));
    EXPECT_THAT(error("2026-02-30T00:00:00Z"), HasSubstr("--time: '2026-02-30T00:00:00Z' is not a date and time that exists"));
    EXPECT_THAT(error("2026-11-23T25:00:00Z"), HasSubstr("'2026-11-23T25:00:00Z'"));
    EXPECT_THAT(error("-2"), HasSubstr("--time: '-2' is not a relative time"));
    EXPECT_THAT(error("-1000000h"), HasSubstr("--time: '-1000000h' lies before 1970"));
    EXPECT_THAT(error("yesterday"), HasSubstr("--time: 'yesterday' is not a time"));
    EXPECT_THAT(error("2026-11-23T14:05:00+2"), HasSubstr("zone offset"));
    EXPECT_THAT(error("2026-11-23T14:05:00Zjunk"), HasSubstr("has 'junk' after the time"));
    EXPECT_THAT(error("2026-11-23T14:05:00."), HasSubstr("no digits after its decimal point"));
    EXPECT_THAT(usage_error([] { parse_duration("--timeout", "1e30h"); }), HasSubstr("--timeout: '1e30h' is not a duration"));
    EXPECT_THAT(usage_error([] { parse_duration("--timeout", "infs"); }), HasSubstr("is not a duration"));
}

// `--foxglove-3d=false` once turned the switch on: a value given to a switch is refused.
TEST(CommandLine, ASwitchGivenAValueIsRefusedNamingIt)
{
    const std::vector<FlagSpec> known{{"--json", false}};
    EXPECT_THAT(usage_error([&] { parse_args({"--json=false"}, known, "cpm history"); }),
                HasSubstr("cpm history: --json is a switch and takes no value ('--json=false'): give --json, or leave it out"));
    EXPECT_TRUE(parse_args({"--json"}, known, "x").has("--json"));
}

TEST(CommandLine, AFlagFollowedByAnotherFlagIsToldItNeedsAValue)
{
    const std::vector<FlagSpec> known{{"--topic", true}, {"--key", true}};
    EXPECT_THAT(usage_error([&] { parse_args({"at", "--topic", "--key", "1"}, known, "cpm history at"); }),
                HasSubstr("cpm history at: --topic needs a value"));
    EXPECT_EQ(parse_args({"--key", "-2"}, known, "x").get("--key"), "-2");  // a negative value is a value
}

TEST(CommandLine, FormattedTimesReadBackAsTheSameInstant)
{
    using cpm::cli::format_time;
    EXPECT_EQ(format_time(1'795'446'323'725'000'000ull), "2026-11-23T15:05:23.725Z");
    EXPECT_EQ(format_time(1'795'446'323'725'000'001ull, 9), "2026-11-23T15:05:23.725000001Z");
    EXPECT_EQ(format_time(1'795'446'323'725'000'000ull, 0), "2026-11-23T15:05:23Z");
    EXPECT_EQ(format_time(0), "-");
    for (uint64_t t : {1ull, 1'795'446'323'725'000'001ull, 4'102'444'800'000'000'000ull})
        EXPECT_EQ(cpm::cli::parse_time("--time", format_time(t, 9), 0), t) << format_time(t, 9);
}
