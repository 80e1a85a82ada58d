// cpm topic …: what is on the lab's topics.
#include "Command.hpp"

#include <cpm/Participant.hpp>
#include <cpm/ReaderAbstract.hpp>

#include <Log.h>

#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdio>

namespace cpm::tools {
namespace {

using cpm::cli::FlagSpec;
using cpm::cli::ParsedArgs;
using cpm::cli::UsageError;
using cpm::cli::parse_args;
using cpm::cli::parse_duration;
using cpm::cli::split_list;

const char* kEchoHelp =
    "usage: cpm topic echo log [--json] [--count N] [--timeout DURATION] [--dds_domain N]\n"
    "\n"
    "Prints the lab's log messages (topic 'log', including the recent ones sent before it started)\n"
    "as they arrive: a table for people, or one JSON object per line with --json. Stops after N\n"
    "messages or after --timeout without one, else on Ctrl-C. Other topics: not yet.\n";

int topic_echo(const std::vector<std::string>& args)
{
    const auto parsed = parse_args(args, {{"--json", false}, {"--count", true}, {"--timeout", true}}, "cpm topic echo");
    const std::string topic = only_positional(parsed, "cpm topic echo", "topic");
    if (topic != "log") {
        throw UsageError("cpm topic echo: topic '" + topic + "' is not supported yet (supported: log)");
    }
    const auto& flags = parsed.flags;
    const bool json = flags.count("--json") > 0;
    uint64_t count = UINT64_MAX;
    if (flags.count("--count")) {
        count = static_cast<uint64_t>(cpm::cli::parse_integer("--count", flags.at("--count"), 1, INT64_MAX));
    }
    const uint64_t timeout_ns = flags.count("--timeout") ? parse_duration("--timeout", flags.at("--timeout")) : 0;

    cpm::Participant participant;
    cpm::ReaderOptions options;
    options.reliable = true;
    options.transient_local = true;
    options.history_depth = 100;
    cpm::ReaderAbstract<Log> reader(participant, "log", options);
    cpm::cli::stop_on_signals();
    static const char* levels[] = {"?", "error", "warn", "info", "debug"};
    if (!json) std::printf("%-20s %-16s %-6s %s\n", "time_ns", "node", "level", "message");
    uint64_t printed = 0;
    auto last = std::chrono::steady_clock::now();
    while (!cpm::cli::stop_requested() && printed < count) {
        if (timeout_ns > 0 && uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                           std::chrono::steady_clock::now() - last).count()) > timeout_ns) {
            std::fprintf(stderr, "cpm topic echo: no message for %s\n", flags.at("--timeout").c_str());
            return 1;
        }
        if (!reader.wait_for_data(std::chrono::milliseconds(100))) continue;
        last = std::chrono::steady_clock::now();
        for (const auto& l : reader.take()) {
            const char* level = l.log_level() <= 4 ? levels[l.log_level()] : "?";
            if (json) {
                nlohmann::json line{{"topic", "log"},
                                    {"data", {{"id", l.id()}, {"content", l.content()},
                                              {"stamp", {{"nanoseconds", l.stamp().nanoseconds()}}},
                                              {"log_level", l.log_level()}}}};
                std::printf("%s\n", line.dump().c_str());
            } else {
                std::printf("%-20llu %-16s %-6s %s\n", static_cast<unsigned long long>(l.stamp().nanoseconds()),
                            l.id().c_str(), level, l.content().c_str());
            }
            std::fflush(stdout);
            if (++printed >= count) break;
        }
    }
    return 0;
}

}  // namespace

std::vector<Command> topic_commands()
{
    return {{"topic", "echo", "print a topic's samples as they arrive", kEchoHelp, topic_echo}};
}

}  // namespace cpm::tools
