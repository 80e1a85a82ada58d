// cpm_history: the lab's history service (KogMo-RTDB over DDS). Records every topic it
// discovers into a time-indexed store and answers historyRequest on historyReply.
#include <cpm/CommandLine.hpp>
#include <cpm/init.hpp>
#include <cpm/rtdb/HistoryService.hpp>
#include <cpm/rtdb/Recording.hpp>

#include <regex>

#include <chrono>
#include <nlohmann/json.hpp>

#include <cstdio>
#include <memory>
#include <thread>

namespace {

const char* kHelp =
    "usage: cpm_history [--include REGEX]... [--exclude REGEX]... [--window 10s] [--topic-window TOPIC=DURATION]...\n"
    "                   [--max-bytes-total N] [--max-bytes-per-topic N] [--status-period 1s]\n"
    "                   [--record FILE [--record-max-bytes N] [--record-name NAME]] [--dds_domain N]\n"
    "\n"
    "Finds topics by DDS discovery and records every one whose name matches an --include pattern\n"
    "(all when none is given) and no --exclude pattern (full-match ECMAScript regexes), types it\n"
    "was never compiled with included: it keeps the serialized payloads and reads the stamps from\n"
    "the Header every cpm type starts with. Each topic keeps --window of history (--topic-window\n"
    "sets one topic's, e.g. --topic-window vehicleState=60s; repeatable) and at most\n"
    "--max-bytes-per-topic payload bytes (default 128 MiB), all topics together at most\n"
    "--max-bytes-total (default 512 MiB; --max-bytes is its older name). Deleted objects\n"
    "(disposed, or their writers gone) stay readable for the window.\n"
    "Answers historyRequest on historyReply (cpm history ..., cpm dump, cpm::HistoryClient) and\n"
    "publishes historyStatus every --status-period. Ends on SIGINT/SIGTERM.\n"
    "--record FILE: also writes every sample it ingests to FILE (SQLite; a new file, never\n"
    "overwritten), with every object's info block and the IDL of cpm's types, kept whole beyond\n"
    "the window: cpm history --file FILE asks it the same questions, cpm play replays it. A writer\n"
    "thread batches the disk writes, so ingest never waits on the disk. --record-max-bytes N: the\n"
    "file stops growing at N bytes. A full disk (or that limit) ends the recording with an error\n"
    "naming the file; what was written stays readable and the live history goes on serving.\n"
    "The file is closed on SIGINT/SIGTERM; after a SIGKILL it still reads up to its last batch.\n";

int run(int argc, char** argv)
{
    auto parsed = cpm::cli::parse_flags(argc, argv,
                                       {{"--include", true, true},
                                        {"--exclude", true, true},
                                        {"--window", true},
                                        {"--topic-window", true, true},
                                        {"--max-bytes-total", true},
                                        {"--max-bytes", true},
                                        {"--max-bytes-per-topic", true},
                                        {"--status-period", true},
                                        {"--record", true},
                                        {"--record-max-bytes", true},
                                        {"--record-name", true}},
                                       "cpm_history");
    cpm::rtdb::ServiceOptions options;
    options.include = parsed.all("--include");
    options.exclude = parsed.all("--exclude");
    for (const auto& [flag, patterns] : {std::pair{"--include", options.include}, std::pair{"--exclude", options.exclude}}) {
        for (const auto& p : patterns) {
            try {
                std::regex check(p);
            } catch (const std::regex_error& e) {
                throw cpm::cli::UsageError(std::string(flag) + " '" + p + "' is not a regular expression: " + e.what());
            }
        }
    }
    options.window_ns = cpm::cli::parse_duration("--window", parsed.get("--window", "10s"));
    if (options.window_ns == 0) throw cpm::cli::UsageError("--window must be longer than 0");
    for (const auto& item : parsed.all("--topic-window")) {
        const auto eq = item.find('=');
        if (eq == std::string::npos || eq == 0) {
            throw cpm::cli::UsageError("cpm_history: --topic-window '" + item + "': expected TOPIC=DURATION (e.g. vehicleState=60s)");
        }
        const uint64_t w = cpm::cli::parse_duration("--topic-window", item.substr(eq + 1));
        if (w == 0) throw cpm::cli::UsageError("cpm_history: --topic-window '" + item + "': the window must be longer than 0");
        options.topic_windows_ns[item.substr(0, eq)] = w;
    }
    if (parsed.has("--max-bytes") && parsed.has("--max-bytes-total"))
        throw cpm::cli::UsageError("cpm_history: --max-bytes is the older name of --max-bytes-total; give one");
    const char* total_flag = parsed.has("--max-bytes") ? "--max-bytes" : "--max-bytes-total";
    options.max_bytes_total =
        static_cast<uint64_t>(cpm::cli::parse_integer(total_flag, parsed.get(total_flag, "536870912"), 1024, 1LL << 40));
    options.max_bytes_per_topic = static_cast<uint64_t>(
        cpm::cli::parse_integer("--max-bytes-per-topic", parsed.get("--max-bytes-per-topic", "134217728"), 1024, 1LL << 40));
    options.status_period_ns = cpm::cli::parse_duration("--status-period", parsed.get("--status-period", "1s"));
    std::shared_ptr<cpm::rtdb::RecordingWriter> recording;
    if (parsed.has("--record")) {
        cpm::rtdb::RecordingOptions ro;
        ro.name = parsed.get("--record-name");
        if (parsed.has("--record-max-bytes"))
            ro.max_bytes = uint64_t(cpm::cli::parse_integer("--record-max-bytes", parsed.get("--record-max-bytes"), 65536, 1LL << 50));
        try {
            recording = std::make_shared<cpm::rtdb::RecordingWriter>(parsed.get("--record"), ro);
        } catch (const std::runtime_error& e) {
            throw cpm::cli::UsageError(std::string("cpm_history: --record: ") + e.what());
        }
        options.sinks.push_back(recording);
    } else if (parsed.has("--record-max-bytes") || parsed.has("--record-name")) {
        throw cpm::cli::UsageError("cpm_history: --record-max-bytes and --record-name go with --record FILE");
    }
    cpm::init(argc, argv);

    cpm::cli::stop_on_signals();
    int status = 0;
    auto service = std::make_unique<cpm::rtdb::HistoryService>(options);
    std::fprintf(stderr, "cpm_history: recording (window %.1f s)%s%s; Ctrl-C ends\n", double(options.window_ns) * 1e-9,
                 recording ? ", every sample also to " : "", recording ? recording->path().c_str() : "");
    bool said = false;
    while (!cpm::cli::stop_requested()) {
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
        if (recording && !said && recording->counters().failed) {
            std::fprintf(stderr, "cpm_history: %s; the live history goes on\n", recording->counters().error.c_str());
            said = true;
        }
    }
    const auto c = service->counters();
    service.reset();  // nothing more is ingested: the recording gets all there was
    nlohmann::json counts{{"topics", c.topics},     {"received", c.received},         {"dropped", c.dropped},
                          {"lost", c.lost},         {"requests", c.requests},         {"bad_requests", c.bad_requests}};
    if (recording) {
        recording->close();
        const auto r = recording->counters();
        counts["recording"] = {{"file", recording->path()}, {"written", r.written}, {"dropped", r.dropped}, {"error", r.error}};
        if (r.failed) status = 1;
    }
    std::printf("%s\n", counts.dump().c_str());
    return status;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "cpm_history", kHelp, run); }
