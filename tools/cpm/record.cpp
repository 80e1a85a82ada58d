// cpm record FILE: what is on the domain, into a recording file (a history service of its own
// with a short window, whose every ingested sample also goes to the file). cpm play FILE: the
// file published again.
#include "Command.hpp"

#include <cpm/Error.hpp>
#include <cpm/Participant.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/read_text_file.hpp>
#include <cpm/rtdb/Csv.hpp>
#include <cpm/rtdb/HistoryService.hpp>
#include <cpm/rtdb/IdlDecoder.hpp>
#include <cpm/rtdb/Player.hpp>
#include <cpm/rtdb/Recording.hpp>

#include <nlohmann/json.hpp>

#include <cctype>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <memory>
#include <sstream>
#include <thread>
#include <unistd.h>

namespace cpm::tools {
namespace {

const char* const kRecordHelp =
    "usage: cpm record FILE [--topics T1,T2,...] [--exclude T1,...] [--duration T] [--max-bytes N]\n"
    "                  [--name NAME] [--dds_domain N]\n"
    "       cpm record import CSV --topic T --type TYPE --out FILE\n"
    "\n"
    "Records what is published on the domain into FILE until Ctrl-C (or --duration): every\n"
    "sample of every topic (or of the --topics named; `*` matches any text, `?` one character),\n"
    "with its commit, data and valid-after times and its payload as sent, every object's info\n"
    "block and the IDL of cpm's types; types cpm does not know keep their payload and stamps.\n"
    "FILE is a new file (an existing one is never overwritten): SQLite, or MCAP when it is named\n"
    "*.mcap (Foxglove and every MCAP tool open it). It is the same file cpm_history --record\n"
    "writes: cpm history --file FILE asks it every question cpm history asks the live service,\n"
    "cpm play FILE publishes it again.\n"
    "--max-bytes N: the file stops growing at N bytes (as on a full disk, the recording then ends\n"
    "with an error; what was written stays readable). Exit code 1 when the recording failed.\n"
    "\n"
    "import: makes a recording from CSV as `cpm history export --csv` writes it (a header row naming\n"
    "the columns: commit_ns, data_ns, valid_after_ns, key, each optional, and fields of TYPE by IDL\n"
    "path such as pose.x; a missing field is 0). Without commit_ns a row is committed at its data\n"
    "time, without data_ns that is header.create_stamp. Every row that does not parse is named by\n"
    "line and column, and nothing is written.\n";

int import_command(const std::vector<std::string>& args)
{
    const std::string command = "cpm record import";
    auto parsed = parse_args(args, {{"--topic", true}, {"--type", true}, {"--out", true}}, command);
    const std::string csv_file = only_positional(parsed, command, "CSV file");
    for (const char* flag : {"--topic", "--type", "--out"}) {
        if (!parsed.has(flag)) throw UsageError(command + ": " + flag + " is required");
    }
    const auto* types = cpm::rtdb::IdlDecoder::lab_types();
    if (!types) throw cpm::Error(command + ": cannot find the lab's IDL files (set CPM_IDL_DIR)");
    if (!types->knows(parsed.get("--type"))) throw UsageError(command + ": --type '" + parsed.get("--type") + "' is not one of cpm's types");
    std::istringstream in(cpm::read_text_file(csv_file, "CSV file"));  // names a directory or a missing file
    try {
        const auto r = cpm::rtdb::csv::import(in, csv_file, parsed.get("--topic"), parsed.get("--type"), *types, parsed.get("--out"));
        std::printf("%s: %llu samples of %llu objects\n", parsed.get("--out").c_str(), (unsigned long long)r.rows,
                    (unsigned long long)r.objects);
    } catch (const cpm::Error& e) {  // rows that do not parse, or the recording that cannot be written
        std::fprintf(stderr, "%s: %s\n", command.c_str(), e.what());
        return 1;
    } catch (const std::runtime_error& e) {
        throw cpm::Error(command + ": " + e.what());
    }
    return 0;
}

int record_command(const std::vector<std::string>& args)
{
    if (!args.empty() && args[0] == "import") return import_command(std::vector<std::string>(args.begin() + 1, args.end()));
    const std::string command = "cpm record";
    auto parsed = parse_args(
        args, {{"--topics", true}, {"--exclude", true}, {"--duration", true}, {"--max-bytes", true}, {"--name", true}}, command);
    const std::string file = only_positional(parsed, command, "FILE (the recording to write)");
    cpm::rtdb::ServiceOptions options;
    if (parsed.has("--topics")) {
        for (const auto& t : split_list("--topics", parsed.get("--topics"))) options.include.push_back(cpm::cli::glob_regex(t));
    }
    if (parsed.has("--exclude")) {
        for (const auto& t : split_list("--exclude", parsed.get("--exclude"))) options.exclude.push_back(cpm::cli::glob_regex(t));
    }
    options.window_ns = 2'000'000'000ull;  // the file keeps everything; the live store only bridges
    const uint64_t duration = parsed.has("--duration") ? parse_duration("--duration", parsed.get("--duration")) : 0;
    if (parsed.has("--duration") && duration == 0) throw UsageError(command + ": --duration must be longer than 0");
    cpm::rtdb::RecordingOptions ro;
    ro.name = parsed.get("--name");
    if (parsed.has("--max-bytes")) ro.max_bytes = uint64_t(cpm::cli::parse_integer("--max-bytes", parsed.get("--max-bytes"), 65536, 1LL << 50));
    std::shared_ptr<cpm::rtdb::RecordingWriter> recording;
    try {
        recording = std::make_shared<cpm::rtdb::RecordingWriter>(file, ro);
    } catch (const std::runtime_error& e) {
        throw UsageError(command + ": " + e.what());
    }
    options.sinks.push_back(recording);

    cpm::cli::stop_on_signals();
    auto service = std::make_unique<cpm::rtdb::HistoryService>(options);
    const bool terminal = ::isatty(STDERR_FILENO);
    std::fprintf(stderr, "cpm record: recording into %s%s\n", file.c_str(), duration ? "" : "; Ctrl-C ends");
    const auto t0 = std::chrono::steady_clock::now();
    auto last_line = t0;
    bool said = false;
    while (!cpm::cli::stop_requested()) {
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
        const auto now = std::chrono::steady_clock::now();
        const auto r = recording->counters();
        if (r.failed && !said) {
            std::fprintf(stderr, "%s%s\n", terminal ? "\n" : "", r.error.c_str());
            said = true;
        }
        if (now - last_line >= std::chrono::seconds(terminal ? 1 : 10)) {
            last_line = now;
            const auto c = service->counters();
            std::fprintf(stderr, terminal ? "\r%.0f s: %llu topics, %llu samples written%s   " : "%.0f s: %llu topics, %llu samples written%s\n",
                         std::chrono::duration<double>(now - t0).count(), (unsigned long long)c.topics, (unsigned long long)r.written,
                         r.dropped ? (", " + std::to_string(r.dropped) + " dropped").c_str() : "");
        }
        if (duration && now - t0 >= std::chrono::nanoseconds(duration)) break;
    }
    if (terminal) std::fprintf(stderr, "\n");
    const auto c = service->counters();
    service.reset();
    recording->close();
    const auto r = recording->counters();
    const nlohmann::json out{{"file", file},          {"topics", c.topics},   {"received", c.received}, {"written", r.written},
                             {"dropped", r.dropped}, {"lost", c.lost},        {"error", r.error}};
    std::printf("%s\n", out.dump().c_str());
    return r.failed ? 1 : 0;
}

const char* const kPlayHelp =
    "usage: cpm play FILE [--rate R] [--from T] [--to T] [--topics T1,T2,...] [--exclude T1,...]\n"
    "                [--wait-for-readers 3s] [--dds_domain N]\n"
    "\n"
    "Publishes a recording's samples again: on their topics, under their type names, with their\n"
    "payloads and stamps as recorded, in the order they were received and with their original\n"
    "spacing divided by --rate (2: twice as fast). Types cpm does not know are replayed too.\n"
    "Run fsm_node, cpm monitor or cpm record against a recorded drive this way.\n"
    "--from/--to: a span of the run, as a time into it on the run's own clock (5s, 90s: lab time\n"
    "in a simulated run, as cpm history --file takes it), a time relative to its end (-10s) or\n"
    "an absolute time (ns, ISO-8601); a span with nothing in it is an error. --topics: only these (`*`, `?` match); by default\n"
    "every topic but the control plane (historyRequest, historyReply, historyStatus,\n"
    "systemTrigger, readyStatus, parameter, parameterRequest), which --topics may name.\n"
    "Waits up to --wait-for-readers for each topic to have a reader, then plays; prints what it\n"
    "sent and how late samples left (p50, p99) as one JSON line.\n";

/// cpm play's options from its flags; `clock` is the recording's when a span is asked for.
cpm::rtdb::PlayOptions play_options(const cpm::cli::ParsedArgs& parsed, const std::string& file, const std::string& command,
                                    cpm::rtdb::RunClock& clock)
{
    cpm::rtdb::PlayOptions options;
    options.rate = cpm::cli::parse_number("--rate", parsed.get("--rate", "1"), 1e-6, 1e6);
    if (parsed.has("--topics")) {
        for (const auto& t : split_list("--topics", parsed.get("--topics"))) options.include.push_back(cpm::cli::glob_regex(t));
    }
    if (parsed.has("--exclude")) {
        for (const auto& t : split_list("--exclude", parsed.get("--exclude"))) options.exclude.push_back(cpm::cli::glob_regex(t));
    }
    if (parsed.has("--wait-for-readers")) options.wait_for_readers_ns = parse_duration("--wait-for-readers", parsed.get("--wait-for-readers"));
    // The span, as commit times (what play goes by): needs the run's clocks, from the file.
    if (parsed.has("--from") || parsed.has("--to")) {
        try {
            clock = cpm::rtdb::recording_clock(file);
        } catch (const std::runtime_error& e) {
            throw cpm::Error(command + ": " + e.what());
        }
    }
    if (parsed.has("--from")) options.from_ns = cpm::rtdb::recording_time(file, clock, "--from", parsed.get("--from"), false);
    if (parsed.has("--to")) options.to_ns = cpm::rtdb::recording_time(file, clock, "--to", parsed.get("--to"), false);
    if (options.to_ns < options.from_ns) throw UsageError(command + ": --to is before --from");
    return options;
}

int play_command(const std::vector<std::string>& args)
{
    const std::string command = "cpm play";
    auto parsed = parse_args(args,
                              {{"--rate", true},
                               {"--from", true},
                               {"--to", true},
                               {"--topics", true},
                               {"--exclude", true},
                               {"--wait-for-readers", true}},
                              command);
    const std::string file = only_positional(parsed, command, "FILE (a recording)");
    cpm::rtdb::RunClock clock;
    const bool span = parsed.has("--from") || parsed.has("--to");
    const cpm::rtdb::PlayOptions options = play_options(parsed, file, command, clock);

    cpm::cli::stop_on_signals();
    std::unique_ptr<cpm::Participant> participant;
    std::unique_ptr<cpm::rtdb::Player> player;
    try {
        // Named cpm_play (unless --node_id names it), so that watchers such as cpm monitor can
        // tell a replay from a live lab.
        participant = std::make_unique<cpm::Participant>(named_participant("cpm_play"));
        player = std::make_unique<cpm::rtdb::Player>(*participant, file, options);
    } catch (const std::runtime_error& e) {
        throw cpm::Error(command + ": " + e.what());
    }
    if (player->topics().empty()) {
        std::fprintf(stderr, "%s: %s holds no samples of the topics asked for\n", command.c_str(), file.c_str());
        return 1;
    }
    std::fprintf(stderr, "cpm play: %zu topics from %s at %gx\n", player->topics().size(), file.c_str(), options.rate);
    const auto stats = player->run([] { return cpm::cli::stop_requested(); });
    for (const auto& t : stats.topics_unread) std::fprintf(stderr, "cpm play: no reader of %s appeared; its samples went to nobody\n", t.c_str());
    const nlohmann::json out{{"file", file},
                             {"published", stats.published},
                             {"failed", stats.failed},
                             {"topics", stats.topics},
                             {"span_s", double(stats.last_commit_ns - stats.first_commit_ns) * 1e-9},
                             {"late_p50_ms", stats.late_p50_ns * 1e-6},
                             {"late_p99_ms", stats.late_p99_ns * 1e-6},
                             {"late_max_ms", stats.late_max_ns * 1e-6}};
    std::printf("%s\n", out.dump().c_str());
    if (stats.published == 0 && stats.failed == 0 && !cpm::cli::stop_requested()) {
        std::string asked;
        for (const char* flag : {"--from", "--to"}) {
            if (parsed.has(flag)) asked += (asked.empty() ? "" : " ") + std::string(flag) + " " + parsed.get(flag);
        }
        if (!span) {
            try {
                clock = cpm::rtdb::recording_clock(file);
            } catch (const std::runtime_error&) {
            }
        }
        char runs[160];
        std::snprintf(runs, sizeof runs, "%s %.1f s", clock.lab_clock ? "its lab clock runs from 0 to" : "it lasts",
                      double(clock.lab_clock ? clock.data_last_ns : clock.ended_ns - clock.started_ns) / 1e9);
        std::fprintf(stderr, "%s: nothing of %s lies in the span asked for (%s; %s)\n", command.c_str(), file.c_str(),
                     asked.empty() ? "the whole run" : asked.c_str(), runs);
        return 1;
    }
    return stats.failed ? 1 : 0;
}

}  // namespace

std::vector<Command> record_commands()
{
    return {{.group = "record", .verb = "", .summary = "record the domain into a recording file (cpm history --file and cpm play read it)", .help = kRecordHelp, .run = record_command},
            {.group = "play", .verb = "", .summary = "publish a recording's samples again with their original spacing", .help = kPlayHelp, .run = play_command}};
}

}  // namespace cpm::tools
