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
