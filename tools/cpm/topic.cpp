// cpm topic …: what is on the lab's topics.
#include "Command.hpp"

#include <cpm/init.hpp>
#include <cpm/rtdb/IdlDecoder.hpp>
#include <cpm/rtdb/TopicProbe.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <deque>
#include <map>
#include <optional>
#include <thread>

namespace cpm::tools {
namespace {

const char* kListHelp =
    "usage: cpm topic list [--json] [--wait DURATION] [--dds_domain N]\n"
    "\n"
    "Every topic on the domain with a writer or a reader, from DDS discovery alone (no history\n"
    "service needed): name, type, how many writers and readers. --wait: how long to listen to\n"
    "discovery first (default 1500ms). --json: one object per topic and line.\n";

const char* kInfoHelp =
    "usage: cpm topic info TOPIC [--json] [--wait DURATION] [--dds_domain N]\n"
    "\n"
    "A topic's type and its writers and readers: each with its participant (node) name,\n"
    "reliability and durability. Exit code 1 when nobody writes or reads it.\n";

const char* kEchoHelp =
    "usage: cpm topic echo TOPIC [--json] [--count N] [--timeout DURATION] [--wait DURATION] [--dds_domain N]\n"
    "\n"
    "Prints a topic's samples as they arrive, subscribing as its first writer offers (a\n"
    "transient-local writer's recent samples too). Types in the lab's IDL are decoded field by\n"
    "field; another type shows its source time and payload_base64. For people one line per sample\n"
    "(the log as a table); --json one object per line: {\"topic\", \"source_ns\", \"data\": {...}}.\n"
    "Stops after N samples, after --timeout without one, else on Ctrl-C. --wait: how long to\n"
    "wait for a writer (default 5s; exit code 1 when none appears).\n";

const char* kHzHelp =
    "usage: cpm topic hz TOPIC [--key K] [--window N] [--duration DURATION] [--json] [--wait DURATION] [--dds_domain N]\n"
    "\n"
    "The rate a topic's samples arrive at here, once a second over the last N arrivals (default\n"
    "1000): mean rate, and the mean, min, max and standard deviation of the period between them.\n"
    "A keyed topic (vehicleState: one instance per car) is measured per key, then all keys\n"
    "together; --key K: only that key (a vehicle id, as cpm history list prints keys).\n"
    "Stops after --duration, else on Ctrl-C. --json: one object per report.\n";

struct Common
{
    bool json = false;
    std::chrono::milliseconds wait{0};
};

std::chrono::milliseconds milliseconds_of(const ParsedArgs& parsed, const char* flag, const char* fallback)
{
    return std::chrono::milliseconds(parse_duration(flag, parsed.get(flag, fallback)) / 1'000'000);
}

/// The topic's entry, if anybody writes or reads it.
std::optional<cpm::rtdb::TopicInfo> find_topic(const cpm::rtdb::TopicProbe& probe, const std::string& topic)
{
    for (auto& t : probe.topics()) {
        if (t.name == topic) return t;
    }
    return std::nullopt;
}

nlohmann::json endpoints_json(const std::vector<cpm::rtdb::Endpoint>& list)
{
    nlohmann::json out = nlohmann::json::array();
    for (const auto& e : list) {
        out.push_back({{"participant", e.participant},
                       {"reliability", e.reliable ? "reliable" : "best_effort"},
                       {"durability", e.transient_local ? "transient_local" : "volatile"}});
    }
    return out;
}

int topic_list(const std::vector<std::string>& args)
{
    const auto parsed = parse_flags(args, {{"--json", false}, {"--wait", true}}, "cpm topic list");
    const auto wait = milliseconds_of(parsed, "--wait", "1500ms");
    cpm::rtdb::TopicProbe probe;
    std::this_thread::sleep_for(wait);
    const auto topics = probe.topics();
    if (!parsed.has("--json")) std::printf("%-32s %-28s %7s %7s\n", "topic", "type", "writers", "readers");
    for (const auto& t : topics) {
        if (parsed.has("--json")) {
            std::printf("%s\n", nlohmann::json{{"topic", t.name}, {"type", t.type_name}, {"keyed", t.keyed},
                                               {"writers", t.writers.size()}, {"readers", t.readers.size()}}
                                    .dump()
                                    .c_str());
        } else {
            std::printf("%-32s %-28s %7zu %7zu\n", t.name.c_str(), t.type_name.c_str(), t.writers.size(), t.readers.size());
        }
    }
    return 0;
}

int topic_info(const std::vector<std::string>& args)
{
    const auto parsed = parse_args(args, {{"--json", false}, {"--wait", true}}, "cpm topic info");
    const std::string topic = only_positional(parsed, "cpm topic info", "topic");
    const auto wait = milliseconds_of(parsed, "--wait", "1500ms");
    cpm::rtdb::TopicProbe probe;
    std::this_thread::sleep_for(wait);  // all of its writers and readers, not only the first
    auto t = find_topic(probe, topic);
    if (!t) {
        std::fprintf(stderr, "cpm topic info: nobody writes or reads topic '%s' on domain %d\n", topic.c_str(),
                     cpm::init_settings().domain_id);
        return 1;
    }
    const auto* types = cpm::rtdb::IdlDecoder::lab_types();
    const auto keys = types ? types->key_members(t->type_name) : std::vector<std::string>{};
    if (parsed.has("--json")) {
        std::printf("%s\n", nlohmann::json{{"topic", t->name}, {"type", t->type_name}, {"keyed", t->keyed}, {"key", keys},
                                           {"known_type", types && types->knows(t->type_name)},
                                           {"writers", endpoints_json(t->writers)}, {"readers", endpoints_json(t->readers)}}
                                .dump()
                                .c_str());
        return 0;
    }
    std::string key_text;
    for (const auto& k : keys) key_text += (key_text.empty() ? "" : ", ") + k;
    std::printf("topic:   %s\ntype:    %s%s\nkey:     %s\n", t->name.c_str(), t->type_name.c_str(),
                types && types->knows(t->type_name) ? "" : " (not in the lab's IDL: shown as bytes)",
                t->keyed ? (key_text.empty() ? "(keyed)" : key_text.c_str()) : "(none)");
    for (const auto* list : {&t->writers, &t->readers}) {
        std::printf("%s %zu\n", list == &t->writers ? "writers:" : "readers:", list->size());
        for (const auto& e : *list) {
            std::printf("  %-28s %-12s %s\n", e.participant.c_str(), e.reliable ? "reliable" : "best_effort",
                        e.transient_local ? "transient_local" : "volatile");
        }
    }
    return 0;
}

/// Subscribes the probe to the topic, or says that nobody writes it.
bool subscribed(cpm::rtdb::TopicProbe& probe, const std::string& command, const std::string& topic,
                std::chrono::milliseconds wait)
{
    if (probe.subscribe(topic, wait)) return true;
    std::fprintf(stderr, "%s: no writer of topic '%s' appeared on domain %d within %lld ms\n", command.c_str(), topic.c_str(),
                 cpm::init_settings().domain_id, (long long)wait.count());
    return false;
}

int topic_echo(const std::vector<std::string>& args)
{
    const auto parsed =
        parse_args(args, {{"--json", false}, {"--count", true}, {"--timeout", true}, {"--wait", true}}, "cpm topic echo");
    const std::string topic = only_positional(parsed, "cpm topic echo", "topic");
    const bool json = parsed.has("--json");
    const uint64_t count = parsed.has("--count") ? uint64_t(cpm::cli::parse_integer("--count", parsed.get("--count"), 1, INT64_MAX))
                                                 : UINT64_MAX;
    const uint64_t timeout_ns = parsed.has("--timeout") ? parse_duration("--timeout", parsed.get("--timeout")) : 0;
    const auto wait = milliseconds_of(parsed, "--wait", "5s");

    cpm::rtdb::TopicProbe probe;
    if (!subscribed(probe, "cpm topic echo", topic, wait)) return 1;
    const std::string type = find_topic(probe, topic).value_or(cpm::rtdb::TopicInfo{}).type_name;
    const auto* types = cpm::rtdb::IdlDecoder::lab_types();
    cpm::cli::stop_on_signals();
    static const char* levels[] = {"?", "error", "warn", "info", "debug"};
    const bool log_table = !json && type == "Log" && types && types->knows("Log");
    if (log_table) std::printf("%-20s %-16s %-6s %s\n", "time_ns", "node", "level", "message");
    uint64_t printed = 0;
    auto last = std::chrono::steady_clock::now();
    while (!cpm::cli::stop_requested() && printed < count) {
        if (timeout_ns > 0 && uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                           std::chrono::steady_clock::now() - last).count()) > timeout_ns) {
            std::fprintf(stderr, "cpm topic echo: no sample of '%s' for %s\n", topic.c_str(), parsed.get("--timeout").c_str());
            return 1;
        }
        auto batch = probe.take(std::chrono::milliseconds(100));
        if (!batch.empty()) last = std::chrono::steady_clock::now();
        for (const auto& s : batch) {
            nlohmann::json line{{"topic", topic}, {"type", type}, {"source_ns", s.source_ns}};
            line.update(cpm::rtdb::describe(types, type, s.payload));
            if (json) {
                std::printf("%s\n", line.dump().c_str());
            } else if (log_table && line.contains("data")) {
                const auto& d = line["data"];
                const unsigned level = d["log_level"].get<unsigned>();
                std::printf("%-20llu %-16s %-6s %s\n", (unsigned long long)d["stamp"]["nanoseconds"].get<uint64_t>(),
                            d["id"].get<std::string>().c_str(), level <= 4 ? levels[level] : "?",
                            d["content"].get<std::string>().c_str());
            } else {
                std::printf("%s: %s\n", topic.c_str(),
                            (line.contains("data") ? line["data"].dump() : "payload " + line["payload_base64"].get<std::string>()).c_str());
            }
            std::fflush(stdout);
            if (++printed >= count) break;
        }
    }
    return 0;
}

/// The periods between arrivals: their mean, spread and extremes.
struct Periods
{
    double mean = 0, sd = 0, lo = 0, hi = 0;
    size_t window = 0;
};

Periods periods_of(const std::deque<uint64_t>& arrivals)
{
    Periods p;
    p.window = arrivals.size();
    std::vector<double> periods;
    for (size_t i = 1; i < arrivals.size(); ++i) periods.push_back(double(arrivals[i] - arrivals[i - 1]) / 1e9);
    if (periods.empty()) return p;
    for (double d : periods) p.mean += d;
    p.mean /= double(periods.size());
    double var = 0;
    for (double d : periods) var += (d - p.mean) * (d - p.mean);
    p.sd = std::sqrt(var / double(periods.size()));
    p.lo = *std::min_element(periods.begin(), periods.end());
    p.hi = *std::max_element(periods.begin(), periods.end());
    return p;
}

int topic_hz(const std::vector<std::string>& args)
{
    const auto parsed = parse_args(args, {{"--json", false}, {"--window", true}, {"--duration", true}, {"--wait", true}, {"--key", true}},
                                   "cpm topic hz");
    const std::string topic = only_positional(parsed, "cpm topic hz", "topic");
    const size_t window = size_t(cpm::cli::parse_integer("--window", parsed.get("--window", "1000"), 2, 1'000'000));
    const uint64_t duration_ns = parsed.has("--duration") ? parse_duration("--duration", parsed.get("--duration")) : UINT64_MAX;
    const auto wait = milliseconds_of(parsed, "--wait", "5s");
    const bool json = parsed.has("--json");
    cpm::rtdb::TopicProbe probe;
    if (!subscribed(probe, "cpm topic hz", topic, wait)) return 1;
    const auto info = find_topic(probe, topic);
    const bool keyed = info && info->keyed;
    const std::string type = info ? info->type_name : "";
    if (parsed.has("--key") && !keyed) {
        std::fprintf(stderr, "cpm topic hz: --key: topic '%s' (%s) has no key; its rate is one\n", topic.c_str(), type.c_str());
        return 2;
    }
    const auto* types = cpm::rtdb::IdlDecoder::lab_types();
    // An instance by its key as cpm prints it (the vehicle id), or by DDS's hash for a type cpm
    // does not know.
    auto key_of = [&](const cpm::rtdb::ProbeSample& s) -> std::string {
        if (!keyed) return "";
        if (types && types->knows(type)) {
            if (auto k = types->key_text(type, s.payload.data(), s.payload.size())) return *k;
        }
        return "#" + s.instance;
    };
    cpm::cli::stop_on_signals();
    std::map<std::string, std::deque<uint64_t>> arrivals;  // by key; "" for an unkeyed topic
    std::deque<uint64_t> all;
    uint64_t total = 0;
    const auto start = std::chrono::steady_clock::now();
    auto next_report = start + std::chrono::seconds(1);
    auto elapsed_ns = [&] {
        return uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - start).count());
    };
    auto report = [&](const std::string& key, const Periods& p, const char* label) {
        const double rate = p.mean > 0 ? 1 / p.mean : 0.0;
        if (json) {
            nlohmann::json j{{"topic", topic}, {"rate_hz", rate}, {"mean_s", p.mean}, {"min_s", p.lo}, {"max_s", p.hi},
                             {"std_s", p.sd}, {"window", p.window}};
            if (keyed) j[label] = std::string(label) == "instances" ? nlohmann::json(std::stoul(key)) : nlohmann::json(key);
            if (!keyed || std::string(label) == "instances") j["samples"] = total;
            std::printf("%s\n", j.dump().c_str());
        } else if (!keyed) {
            std::printf("average rate: %.3f Hz\n  period mean: %.4f s  min: %.4f s  max: %.4f s  std dev: %.5f s  window: %zu\n", rate, p.mean,
                        p.lo, p.hi, p.sd, p.window);
        } else {
            std::printf("%-24s %9.3f Hz  period mean %.4f s  min %.4f s  max %.4f s  std dev %.5f s  window %zu\n",
                        (std::string(label) == "instances" ? "all " + key + " keys" : topic + "/" + key).c_str(), rate, p.mean, p.lo,
                        p.hi, p.sd, p.window);
        }
    };
    while (!cpm::cli::stop_requested() && elapsed_ns() < duration_ns) {
        for (const auto& s : probe.take(std::chrono::milliseconds(50))) {
            const std::string key = key_of(s);
            if (parsed.has("--key") && key != parsed.get("--key")) continue;
            auto& mine = arrivals[key];
            mine.push_back(s.received_ns);
            if (mine.size() > window) mine.pop_front();
            all.push_back(s.received_ns);
            if (all.size() > window) all.pop_front();
            ++total;
        }
        if (std::chrono::steady_clock::now() < next_report) continue;
        next_report += std::chrono::seconds(1);
        if (all.size() < 2) {
            if (!json) std::printf("no samples of '%s'%s yet\n", topic.c_str(), parsed.has("--key") ? (" key " + parsed.get("--key")).c_str() : "");
            continue;
        }
        // A keyed topic per key (two cars at 50 Hz are two 50 Hz instances, not one at 100 Hz),
        // then every key together.
        for (const auto& [key, times] : arrivals) {
            if (times.size() >= 2) report(key, periods_of(times), "key");
        }
        if (keyed && !parsed.has("--key")) report(std::to_string(arrivals.size()), periods_of(all), "instances");
        if (keyed && !json) std::printf("\n");
        std::fflush(stdout);
    }
    return 0;
}

}  // namespace

std::vector<Command> topic_commands()
{
    return {{.group = "topic", .verb = "list", .summary = "every topic on the domain, from DDS discovery (no history service needed)", .help = kListHelp, .run = topic_list},
            {.group = "topic", .verb = "info", .summary = "a topic's type, writers and readers", .help = kInfoHelp, .run = topic_info},
            {.group = "topic", .verb = "echo", .summary = "print any topic's samples as they arrive, decoded field by field", .help = kEchoHelp, .run = topic_echo},
            {.group = "topic", .verb = "hz", .summary = "the rate a topic's samples arrive at: mean, min, max and std of the period", .help = kHzHelp, .run = topic_hz}};
}

}  // namespace cpm::tools
