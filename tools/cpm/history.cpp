// cpm history ... and cpm dump: the history service's answers on the command line.
#include "Command.hpp"

#include <cpm/rtdb/Csv.hpp>
#include <cpm/rtdb/Diff.hpp>
#include <cpm/rtdb/HistoryJson.hpp>
#include <cpm/rtdb/IdlDecoder.hpp>
#include <cpm/rtdb/Recording.hpp>

#include <cpm/CommandLine.hpp>
#include <cpm/HistoryClient.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/read_text_file.hpp>
#include <cpm/topics.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <map>
#include <sstream>
#include <memory>
#include <regex>
#include <set>
#include <sys/stat.h>

namespace cpm::tools {
namespace {

const char* const kHistoryHelp =
    "usage: cpm history list|search|wait-object|changes|latest|at|older|younger|range|wait|successor|snapshot|marks|save|export|diff\n"
    "                   [flags] [--json]\n"
    "\n"
    "                   [--file recording.db]\n"
    "\n"
    "Asks the history service (cpm_history, on this domain) about the recent past, or, with\n"
    "--file, a recording of a finished run (cpm_history --record, cpm record, cpm lab run): the\n"
    "same verbs, flags and JSON; there \"now\" (for -2s, ages and rates) is the run's end. --file\n"
    "takes an SQLite or MCAP recording, a run's folder, a folder of a split recording, or --file\n"
    "again for each file of one recording.\n"
    "  list                                 every object held (alive and deleted-but-held)\n"
    "  search [--name REGEX] [--type T] [--parent OID] [--creator NAME|GUID] [--alive-at T]\n"
    "  wait-object [search flags] [--timeout 10s]   the first object matching, once one exists\n"
    "  changes --since T                    objects created or deleted after T\n"
    "  latest --topic NAME [--key K]\n"
    "  at|older|younger --topic NAME [--key K] --time T [--by commit|data]\n"
    "                                       newest at or before / strictly before / after T\n"
    "  range --topic NAME [--key K] --from T --to T [--by commit|data] [--limit N] [--partial-ok]\n"
    "                                       the samples of [from, to), oldest first, at most --limit\n"
    "                                       (default 1000, up to 100000; a cut answer ends with a line\n"
    "                                       saying where the rest starts). A span reaching back past\n"
    "                                       the history's window answers what is held with status\n"
    "                                       partial and exit 1, exit 0 with --partial-ok\n"
    "  wait --topic NAME [--key K] [--time T] [--timeout 10s]   newest committed after T (default now)\n"
    "  successor --topic NAME [--key K] --time T [--timeout 10s]  exactly the next one, or 'gap'\n"
    "  snapshot --objects TOPIC[/KEY],... --time T [--by commit|data]   one consistent cut\n"
    "  export --topic NAME [--key K] [--from T] [--to T] --csv\n"
    "                                       every sample (of every key without --key) as CSV, in\n"
    "                                       commit order: commit_ns, data_ns, valid_after_ns, key, then\n"
    "                                       the fields by IDL path (pose.x); cpm record import reads it\n"
    "  marks                                the bookmarks (cpm lab mark), oldest first: time, source, text\n"
    "  save NAME [--before 30s] [--after 10s] [--topics A,B]   the dash-cam: the live service writes\n"
    "                                       what it holds of the last --before and what comes in the\n"
    "                                       next --after (data times) into a new recording NAME in its\n"
    "                                       save folder (cpm_history --save-dir), and goes on serving\n"
    "  export --mcap|--sqlite OUT [--topics A,B] [--from T] [--to T] [--by commit|data]   (with --file)\n"
    "                                       a new recording OUT of the topics asked for (all without\n"
    "                                       --topics), every sample byte for byte: MCAP opens in\n"
    "                                       Foxglove (IDL schemas, CDR messages, indexed); a run\n"
    "                                       folder's scenario and summary go with it as metadata;\n"
    "                                       --foxglove-3d: the cars' poses also as FrameTransform on\n"
    "                                       /tf (frames car_<id>, car_<id>_estimate in map) for its 3D panel\n"
    "  diff OTHER [--topics A,B] [--all]    (with --file) compares two recordings (two runs of a\n"
    "                                       scenario, of a controller) sample for sample by data time\n"
    "                                       and payload; prints the first difference of each topic and\n"
    "                                       key, naming the field; exit 0 when identical, 1 when not.\n"
    "                                       Leaves out the clock's traffic, the log and the history's status\n"
    "                                       (wall-clock times) unless --all\n"
    "--key: a vehicle id, or the key as `cpm history list` prints it. Times: nanoseconds,\n"
    "ISO-8601 UTC (2026-11-23T14:05:00.25Z) or relative to now (-2s). --by commit (default):\n"
    "when the service received it; data: the sample's create_stamp.\n"
    "With --file, also a time into the run (20s, 1.5s): on the run's own clock, lab time in a\n"
    "simulated run (20s: 20 s of lab time) and since its start in a real one; -2s and now count\n"
    "back from the end of the clock --by names (the lab clock's end with --by data).\n"
    "Output: a table, or one JSON object per line (--json) with every field of a cpm type\n"
    "decoded; a type cpm does not know is shown with its stamps and payload_base64.\n"
    "Exit code 0 when the answer is ok; 1 with the status (not_found, evicted, not_yet, timeout,\n"
    "gap, partial) or the service's error on stderr; 2 on a usage error.\n";

const char* const kDumpHelp =
    "usage: cpm dump [--alive] [--all] [--json] [--file recording.db] [--dds_domain N]\n"
    "\n"
    "One table of every object the history service holds (like kogmo_rtdb_dump -a), oldest first:\n"
    "oid, name, type, creator, created and deleted (UTC), samples held, samples lost, rate, age of\n"
    "the newest sample. Processes are objects too; the cpm command's own are left out unless --all.\n"
    "--alive: only objects alive now. An oid prints as its slot, with .generation once the slot was\n"
    "used before (7, 7.2); --oid and --parent take it as printed.\n";


using cpm::cli::UsageError;

/// The command's participant: UDP loopback only. A short-lived process that reuses the
/// shared-memory port of one that just exited is not reached by the service's replies
/// (Fast DDS 2.9 keeps sending to the old port for a while).
cpm::Participant& client_participant()
{
    static cpm::Participant p = [] {
        auto o = cpm::ParticipantOptions::from_init();
        o.shared_memory = false;
        return cpm::Participant(o);
    }();
    return p;
}

/// Where the answers come from: the live history service, or a recording (--file FILE), whose
/// "now" (for relative times, ages and rates) is the end of the recorded run and whose types are
/// the IDL it carries.
struct Source
{
    std::unique_ptr<cpm::HistoryClient> client;
    uint64_t now = 0;
    std::shared_ptr<const cpm::rtdb::LoadedRecording> recording;

    /// A time flag's value (see cpm::cli::parse_time) against this source's now.
    std::string file;                 ///< the recording, or "" for the live service
    cpm::rtdb::RunClock clock;        ///< the recording's clocks

    /// A time flag's value: against a recording, on the clock the query goes by (see
    /// cpm::rtdb::recording_time: "20s" is 20 s into the run, lab time in a simulated one); live,
    /// against now.
    uint64_t time(const std::string& flag, const std::string& text, bool by_data = false) const
    {
        if (!file.empty()) return cpm::rtdb::recording_time(file, clock, flag, text, by_data);
        if (cpm::rtdb::is_time_into_run(text)) {
            throw UsageError(flag + ": '" + text + "' is a time into a run, which only a recording has (--file); live, ask -" + text +
                             " (before now) or give an absolute time");
        }
        return cpm::cli::parse_time(flag, text, now);
    }
    const cpm::rtdb::IdlDecoder& decoder() const
    {
        if (recording && recording->types) return *recording->types;
        const auto* types = cpm::rtdb::IdlDecoder::lab_types();
        if (!types) throw cpm::Error("cannot find the lab's IDL files (set CPM_IDL_DIR)");
        return *types;
    }
};

Source open_source(const std::string& file, const std::string& command)
{
    Source s;
    if (file.empty()) {
        s.client = std::make_unique<cpm::HistoryClient>(client_participant());
        s.now = cpm::get_time_ns();
        return s;
    }
    try {
        s.recording = std::make_shared<cpm::rtdb::LoadedRecording>(cpm::rtdb::load_recording(file));
    } catch (const std::runtime_error& e) {
        throw cpm::Error(command + ": --file: " + e.what());
    }
    if (!s.recording->warning.empty()) std::fprintf(stderr, "%s: %s\n", command.c_str(), s.recording->warning.c_str());
    s.client = std::make_unique<cpm::HistoryClient>(cpm::rtdb::recording_backend(s.recording));
    s.now = s.recording->ended_ns;
    s.file = file;
    try {
        s.clock = cpm::rtdb::recording_clock(file);
    } catch (const std::runtime_error& e) {  // damaged beyond its samples: the loaded part's span
        s.clock.started_ns = s.recording->started_ns;
        s.clock.ended_ns = s.clock.data_last_ns = s.recording->ended_ns;
    }
    return s;
}

std::string age_text(double s)
{
    char buf[32];
    if (s < 0) return "-";
    std::snprintf(buf, sizeof buf, s < 10 ? "%.3f s" : "%.1f s", s);
    return buf;
}

/// --oid / --parent: the number as the table prints it ("7", "7.2") or as JSON gives it.
uint64_t parse_oid(const std::string& flag, const std::string& text)
{
    if (auto oid = cpm::rtdb::oid_from_text(text)) return *oid;
    throw UsageError(flag + ": '" + text + "' is not an oid (as cpm dump prints it: 7, or 7.2 for slot 7's second object)");
}

/// The processes of cpm's own command and probes: the dump leaves them out unless --all.
bool own_tool(const HistoryObject& o)
{
    return o.is_process() && (o.name() == "cpm" || o.name().rfind("cpm_topic_probe", 0) == 0);
}

void print_objects(const HistoryReply& reply, bool json, uint64_t now, bool show_all = true)
{
    std::vector<HistoryObject> rows;
    for (const auto& o : reply.objects()) {
        if (show_all || !own_tool(o)) rows.push_back(o);
    }
    std::stable_sort(rows.begin(), rows.end(), [](const HistoryObject& a, const HistoryObject& b) { return a.created_ts() < b.created_ts(); });
    if (json) {
        for (const auto& o : rows) std::printf("%s\n", cpm::rtdb::object_json(o, now).dump().c_str());
        return;
    }
    std::printf("%-6s %-28s %-22s %-18s %-24s %-24s %8s %6s %9s %10s\n", "oid", "name", "type", "creator", "created (UTC)",
                "deleted (UTC)", "samples", "lost", "rate", "newest");
    for (const auto& o : rows) {
        const auto j = cpm::rtdb::object_json(o, now);
        char rate[32];
        const double hz = j["rate_hz"].get<double>();
        if (hz > 0) std::snprintf(rate, sizeof rate, "%.1f Hz", hz);
        else std::snprintf(rate, sizeof rate, "-");
        std::printf("%-6s %-28s %-22s %-18s %-24s %-24s %8llu %6llu %9s %10s\n", cpm::rtdb::oid_text(o.oid()).c_str(), o.name().c_str(),
                    o.type_name().c_str(), o.creator().c_str(), cpm::cli::format_time(o.created_ts()).c_str(), cpm::cli::format_time(o.deleted_ts()).c_str(),
                    (unsigned long long)o.samples_held(), (unsigned long long)o.samples_lost(), rate, age_text(j["newest_age_s"]).c_str());
    }
}

/// `history changes`: one row per creation or deletion after `since`, in time order.
void print_changes(const HistoryReply& reply, bool json, uint64_t since, uint64_t now)
{
    struct Event
    {
        uint64_t t;
        const char* kind;
        const HistoryObject* o;
    };
    std::vector<Event> events;
    std::set<uint64_t> seen;  // an object created and deleted since comes in both of the reply's lists
    for (const auto& o : reply.objects()) {
        if (!seen.insert(o.oid()).second) continue;
        if (o.created_ts() > since) events.push_back({o.created_ts(), "created", &o});
        if (o.deleted_ts() > since) events.push_back({o.deleted_ts(), "deleted", &o});
    }
    std::stable_sort(events.begin(), events.end(), [](const Event& a, const Event& b) { return a.t < b.t; });
    if (!json) std::printf("%-24s %-8s %-6s %-28s %-22s %s\n", "time (UTC)", "event", "oid", "name", "type", "creator");
    for (const auto& e : events) {
        if (json) {
            auto j = cpm::rtdb::object_json(*e.o, now);
            j["event"] = e.kind;
            j["t_ns"] = e.t;
            std::printf("%s\n", j.dump().c_str());
        } else {
            std::printf("%-24s %-8s %-6s %-28s %-22s %s\n", cpm::cli::format_time(e.t).c_str(), e.kind, cpm::rtdb::oid_text(e.o->oid()).c_str(),
                        e.o->name().c_str(), e.o->type_name().c_str(), e.o->creator().c_str());
        }
    }
}

/// A decoded value for people: floats to 6 significant digits, NaN and infinities by name.
std::string value_text(const nlohmann::json& v)
{
    if (v.is_number_float()) {
        const double d = v.get<double>();
        if (std::isnan(d)) return "NaN";
        if (std::isinf(d)) return d > 0 ? "inf" : "-inf";
        char buf[32];
        std::snprintf(buf, sizeof buf, "%.6g", d);
        return buf;
    }
    if (v.is_string()) return v.get<std::string>();
    if (v.is_array()) {
        std::string out = "[";
        for (size_t i = 0; i < v.size(); ++i) out += (i ? ", " : "") + value_text(v[i]);
        return out + "]";
    }
    if (v.is_object()) {
        std::string out = "{";
        for (auto it = v.begin(); it != v.end(); ++it) out += (it == v.begin() ? "" : ", ") + it.key() + ": " + value_text(it.value());
        return out + "}";
    }
    return v.dump();
}

/// One field a line, nested structs as dotted names ("pose.x"), time stamps as times.
void print_fields(const nlohmann::json& data, const std::string& prefix)
{
    for (auto it = data.begin(); it != data.end(); ++it) {
        const std::string name = prefix + it.key();
        const auto& v = it.value();
        if (v.is_object() && v.size() == 1 && v.contains("nanoseconds")) {  // a TimeStamp
            const uint64_t ns = v["nanoseconds"].get<uint64_t>();
            std::printf("  %-32s %s (%llu ns)\n", name.c_str(), cpm::cli::format_time(ns, 9).c_str(), (unsigned long long)ns);
        } else if (v.is_object()) {
            print_fields(v, name + ".");
        } else {
            std::printf("  %-32s %s\n", name.c_str(), value_text(v).c_str());
        }
    }
}

void print_samples(const HistoryReply& reply, bool json, const cpm::rtdb::IdlDecoder& types)
{
    for (size_t i = 0; i < reply.samples().size(); ++i) {
        const auto& s = reply.samples()[i];
        // A snapshot names one object per sample; other answers are about the one object.
        const HistoryObject* o = reply.objects().size() == reply.samples().size() ? &reply.objects()[i]
                                 : reply.objects().empty()                        ? nullptr
                                                                                  : &reply.objects()[0];
        auto j = cpm::rtdb::sample_json(s, o, &types);
        if (json) {
            std::printf("%s\n", j.dump().c_str());
            continue;
        }
        if (i > 0) std::printf("\n");
        std::printf("%s%s%s\n", o ? o->name().c_str() : "(unknown object)", o ? "  " : "",
                    o ? ("(" + o->type_name() + ")").c_str() : "");
        if (s.status() != "ok") std::printf("  %-32s %s\n", "status", s.status().c_str());
        const bool source_time = o && o->data_time() == "source_timestamp";
        std::printf("  %-32s %s\n", "committed", cpm::cli::format_time(s.commit_ns(), 9).c_str());
        std::printf("  %-32s %s%s\n", "data time", cpm::cli::format_time(s.data_ns(), 9).c_str(),
                    source_time ? "  (the writer's source timestamp: the type has no Header)" : "");
        if (!source_time) std::printf("  %-32s %s\n", "valid after", cpm::cli::format_time(s.valid_after_ns(), 9).c_str());
        if (j.contains("data")) print_fields(j["data"], "");
        else std::printf("  %-32s %s\n", "payload_base64", j["payload_base64"].get<std::string>().c_str());
    }
}

/// The verbs that answer with objects, not samples.
bool about_objects(const std::string& verb) { return verb == "list" || verb == "search" || verb == "wait-object" || verb == "changes"; }

/// The request a verb's flags ask for, against the source's clocks. Throws UsageError naming a
/// missing or wrong flag.
HistoryRequest request_of(const std::string& verb, const cpm::cli::ParsedArgs& parsed, const Source& source)
{
    const std::string command = "cpm history " + verb;
    const bool by_data = parsed.get("--by", "commit") == "data";
    // Objects' times (created, deleted) are the service's: --since and --alive-at go by commit.
    auto parse_time = [&](const std::string& flag) {
        return source.time(flag, parsed.get(flag), by_data && flag != "--since" && flag != "--alive-at");
    };
    auto require = [&](const char* flag, const std::string& what) {
        if (!parsed.has(flag)) throw UsageError(command + ": " + what);
    };
    // The verbs are the request kinds, but for two spelled as a person types them.
    const std::string kind_name = verb == "wait" ? "wait_next" : verb == "wait-object" ? "wait_object" : verb;
    const auto kind = cpm::history::kind_from(kind_name);
    if (!kind || *kind == cpm::history::Kind::info) throw UsageError("cpm: unknown command 'cpm history " + verb + "' (see cpm history --help)");
    const auto by = cpm::history::by_from(parsed.get("--by", "commit"));
    if (!by) throw UsageError(command + ": --by '" + parsed.get("--by") + "': expected commit or data");
    HistoryRequest rq = cpm::HistoryClient::make(*kind, parsed.get("--topic"), parsed.get("--key"), 0, *by);
    if (parsed.has("--oid")) rq.oid(parse_oid("--oid", parsed.get("--oid")));
    if (!about_objects(verb) && verb != "snapshot" && rq.topic().empty() && !rq.oid()) {
        throw UsageError(command + ": --topic NAME (and --key K) is required");
    }
    if (verb == "at" || verb == "older" || verb == "younger" || verb == "snapshot") {
        require("--time", "--time T is required (ns, ISO-8601 or relative such as -2s)");
        rq.t0(parse_time("--time"));
    }
    if (verb == "range") {
        if (!parsed.has("--from") || !parsed.has("--to")) throw UsageError(command + ": --from T and --to T are required");
        rq.t0(parse_time("--from"));
        rq.t1(parse_time("--to"));
        if (rq.t1() < rq.t0()) throw UsageError(command + ": --to is before --from");
    }
    if (verb == "wait" || verb == "successor") rq.t0(parsed.has("--time") ? parse_time("--time") : source.now);
    if (verb == "changes") {
        require("--since", "--since T is required");
        rq.t0(parse_time("--since"));
    }
    if (parsed.has("--timeout")) rq.timeout_ns(cpm::cli::parse_duration("--timeout", parsed.get("--timeout")));
    else if (verb == "wait" || verb == "successor" || verb == "wait-object") rq.timeout_ns(10'000'000'000ull);
    if (parsed.has("--limit")) rq.limit(uint32_t(cpm::cli::parse_integer("--limit", parsed.get("--limit"), 1, 100000)));
    if (verb == "snapshot") {
        require("--objects", "--objects TOPIC[/KEY],... is required");
        for (const auto& o : cpm::cli::split_list("--objects", parsed.get("--objects"))) rq.objects().push_back(o);
    }
    rq.name_regex(parsed.get("--name"));
    rq.type_name(parsed.get("--type"));
    if (parsed.has("--parent")) rq.parent(parse_oid("--parent", parsed.get("--parent")));
    rq.creator(parsed.get("--creator"));
    if (parsed.has("--alive-at")) rq.alive_at(parse_time("--alive-at"));
    return rq;
}

/// The end of an answer that is not the whole span asked for says so, on stderr and on stdout
/// (a script reading --json sees it as the last line), with how to get the rest.
void say_incomplete(const std::string& verb, const HistoryRequest& rq, const HistoryReply& reply, bool json)
{
    if (reply.samples().empty()) return;
    const std::string object = rq.topic().empty() ? "" : rq.topic() + (rq.key().empty() ? "" : "/" + rq.key());
    const bool by_data = rq.by() == "data";
    auto closing_line = [&](const std::string& said, nlohmann::json line) {
        std::fprintf(stderr, "cpm history %s: %s%s\n", verb.c_str(), object.empty() ? "" : (object + ": ").c_str(), said.c_str());
        if (!json) {
            std::printf("\n%s\n", said.c_str());
            return;
        }
        if (!object.empty()) line.update({{"topic", rq.topic()}, {"key", rq.key()}});
        line["message"] = said;
        std::printf("%s\n", line.dump().c_str());
    };
    if (reply.status() == "partial" && verb == "range") {
        const auto& first = reply.samples().front();
        const uint64_t first_held = by_data ? first.data_ns() : first.commit_ns();
        closing_line("partial: the span's start (" + cpm::cli::format_time(rq.t0(), 9) + ") is older than what the history holds; the samples " +
                         "shown start at " + cpm::cli::format_time(first_held, 9) + " (--partial-ok: take what is held, exit 0)",
                     {{"status", "partial"}, {"from_ns", rq.t0()}, {"first_held_ns", first_held}});
    }
    if (reply.truncated()) {
        const auto& last = reply.samples().back();
        const uint64_t next = by_data ? last.data_ns() : last.commit_ns() + 1;
        closing_line("cut at --limit " + std::to_string(reply.samples().size()) + ": more samples matched; the oldest are shown. The rest: --from " +
                         std::to_string(next) + (by_data ? " (repeats the samples of that data time)" : "") + ", or a larger --limit",
                     {{"status", "truncated"}, {"limit", reply.samples().size()}, {"next_from_ns", next}});
    }
}

int history_command(const std::string& verb, const std::vector<std::string>& args, const std::string& file)
{
    const std::string command = "cpm history " + verb;
    auto parsed = cpm::cli::parse_flags(args,
                                       {{"--topic", true},   {"--key", true},     {"--oid", true},      {"--time", true},
                                        {"--by", true},      {"--from", true},    {"--to", true},       {"--timeout", true},
                                        {"--limit", true},   {"--objects", true}, {"--name", true},     {"--type", true},
                                        {"--parent", true},  {"--creator", true}, {"--alive-at", true}, {"--since", true},
                                        {"--partial-ok", false}, {"--json", false}},
                                       command);
    const Source source = open_source(file, command);
    const HistoryRequest rq = request_of(verb, parsed, source);
    const HistoryReply reply = source.client->request(rq);
    const bool json = parsed.has("--json");
    const auto status = cpm::history::status_from(reply.status()).value_or(cpm::history::Status::error);
    if (status == cpm::history::Status::error || status == cpm::history::Status::unknown_object) {
        std::fprintf(stderr, "cpm history %s: %s%s\n", verb.c_str(),
                     status == cpm::history::Status::error ? "the service refused the request: " : "", reply.error().c_str());
        return 1;
    }
    if (verb == "changes") print_changes(reply, json, rq.t0(), source.now);
    else if (about_objects(verb)) print_objects(reply, json, source.now);
    else print_samples(reply, json, source.decoder());
    say_incomplete(verb, rq, reply, json);
    if (reply.lost() > 0)
        std::fprintf(stderr, "cpm history %s: %llu samples between the first and the last shown never reached the service\n",
                     verb.c_str(), (unsigned long long)reply.lost());
    if (status == cpm::history::Status::partial && verb == "range") return parsed.has("--partial-ok") ? 0 : 1;
    if (status != cpm::history::Status::ok) {
        const std::string what = rq.topic().empty() ? "" : rq.topic() + (rq.key().empty() ? "" : "/" + rq.key()) + ": ";
        std::fprintf(stderr, "cpm history %s: %s%s\n", verb.c_str(), what.c_str(), reply.status().c_str());
        if (json && reply.samples().empty()) {
            nlohmann::json miss{{"status", reply.status()}};
            if (!rq.topic().empty()) miss.update({{"topic", rq.topic()}, {"key", rq.key()}});
            std::printf("%s\n", miss.dump().c_str());
        }
        return 1;
    }
    return 0;
}

int dump_command(const std::vector<std::string>& args)
{
    auto parsed = cpm::cli::parse_flags(args, {{"--json", false}, {"--alive", false}, {"--all", false}, {"--file", true}}, "cpm dump");
    const Source source = open_source(parsed.get("--file"), "cpm dump");
    const bool alive = parsed.has("--alive");
    HistoryRequest rq = cpm::HistoryClient::make(alive ? cpm::history::Kind::search : cpm::history::Kind::list, "", "");
    if (alive) rq.alive_at(source.now);
    const HistoryReply reply = source.client->request(rq);
    if (reply.status() != "ok") {
        std::fprintf(stderr, "cpm dump: %s: %s\n", reply.status().c_str(), reply.error().c_str());
        return 1;
    }
    print_objects(reply, parsed.has("--json"), source.now, parsed.has("--all"));
    return 0;
}

/// `cpm history export --topic T [--key K] --csv`: every sample of the object (or of every key
/// of the topic), in commit order, as CSV (cpm::rtdb::csv).
/// `cpm history --file REC export --mcap|--sqlite OUT`: the recording (some topics, a span of
/// it) into a new recording file.
int export_recording_command(const cpm::cli::ParsedArgs& parsed, const std::string& file, const std::string& command)
{
    if (file.empty()) throw UsageError(command + ": --mcap and --sqlite copy a recording: give it with --file REC");
    for (const char* f : {"--topic", "--key", "--csv"}) {
        if (parsed.has(f)) throw UsageError(command + ": " + f + " goes with --csv; a recording is exported by --topics A,B");
    }
    const bool mcap = parsed.has("--mcap");
    if (mcap && parsed.has("--sqlite")) throw UsageError(command + ": --mcap or --sqlite, not both");
    const std::string out = parsed.get(mcap ? "--mcap" : "--sqlite");
    const Source source = open_source(file, command);
    cpm::rtdb::ExportOptions o{.format = mcap ? "mcap" : "sqlite"};
    o.by_data = parsed.get("--by", "commit") == "data";
    o.foxglove_3d = parsed.has("--foxglove-3d");
    if (o.foxglove_3d && !mcap) throw UsageError(command + ": --foxglove-3d goes with --mcap");
    if (!o.by_data && parsed.get("--by", "commit") != "commit") throw UsageError(command + ": --by '" + parsed.get("--by") + "': expected commit or data");
    if (parsed.has("--from")) o.from_ns = source.time("--from", parsed.get("--from"), o.by_data);
    if (parsed.has("--to")) o.to_ns = source.time("--to", parsed.get("--to"), o.by_data);
    if (o.to_ns < o.from_ns) throw UsageError(command + ": --to is before --from");
    std::stringstream topics(parsed.get("--topics"));
    for (std::string t; std::getline(topics, t, ',');) {
        if (!t.empty()) o.topics.push_back(t);
    }
    // A run folder's scenario and summary travel with its recording.
    const std::filesystem::path dir = std::filesystem::is_directory(file) ? std::filesystem::path(file) : std::filesystem::path(file).parent_path();
    std::map<std::string, std::string> run;
    for (const char* f : {"scenario.yaml", "summary.json"}) {
        if (std::filesystem::is_regular_file(dir / f)) run[std::filesystem::path(f).stem().string()] = cpm::read_text_file((dir / f).string(), "run file");
    }
    if (!run.empty()) o.metadata["cpm.run"] = run;
    const auto counts = cpm::rtdb::export_recording(file, out, o);
    std::printf("%s: %llu samples of %llu objects from %s\n", out.c_str(), (unsigned long long)counts.samples, (unsigned long long)counts.objects,
                file.c_str());
    return 0;
}

/// `cpm history marks [--json]`: the bookmarks (cpm lab mark, the monitor's Mark), oldest first.
/// `cpm history --file A diff B [--topics A,B] [--all] [--json]`: the first difference of each topic and key.
int diff_command(const std::vector<std::string>& args, const std::string& file)
{
    const std::string command = "cpm history diff";
    const auto parsed = cpm::cli::parse_args(args, {{"--topics", true}, {"--all", false}, {"--json", false}}, command);
    if (file.empty()) throw UsageError(command + ": which recordings? cpm history --file A diff B");
    if (parsed.positional.size() != 1)
        throw UsageError(command + ": give the other recording once (cpm history --file A diff B); got " + std::to_string(parsed.positional.size()));
    cpm::rtdb::DiffOptions o;
    if (parsed.has("--all")) o.exclude.clear();
    std::stringstream topics(parsed.get("--topics"));
    for (std::string t; std::getline(topics, t, ',');) {
        if (!t.empty()) o.topics.push_back(t);
    }
    const auto a = cpm::rtdb::load_recording(file);
    const auto b = cpm::rtdb::load_recording(parsed.positional[0]);
    const auto result = cpm::rtdb::diff_recordings(a, b, o);
    for (const auto& d : result.differences) {
        const std::string name = d.key.empty() ? d.topic : d.topic + "/" + d.key;
        if (parsed.has("--json")) {
            std::printf("%s\n", nlohmann::json{{"topic", d.topic}, {"key", d.key}, {"index", d.index}, {"data_ns_a", d.data_ns_a},
                                               {"data_ns_b", d.data_ns_b}, {"what", d.what}}.dump().c_str());
        } else {
            std::printf("%s: sample %llu: %s\n", name.c_str(), (unsigned long long)d.index, d.what.c_str());
        }
    }
    if (parsed.has("--json")) {
        std::printf("%s\n", nlohmann::json{{"compared", result.objects}, {"equal_samples", result.samples}, {"identical", result.identical()}}.dump().c_str());
    } else {
        std::printf("%llu topic/key(s) compared, %llu samples equal: %s\n", (unsigned long long)result.objects, (unsigned long long)result.samples,
                    result.identical() ? "identical" : (std::to_string(result.differences.size()) + " differ").c_str());
    }
    return result.identical() ? 0 : 1;
}

int marks_command(const std::vector<std::string>& args, const std::string& file)
{
    const std::string command = "cpm history marks";
    auto parsed = cpm::cli::parse_flags(args, {{"--json", false}}, command);
    const Source source = open_source(file, command);
    // Each marking process's writer is an object of its own (the topic is unkeyed): all of them.
    HistoryRequest find = cpm::HistoryClient::make(cpm::history::Kind::search, "", "");
    find.name_regex(std::string("^") + cpm::topics::bookmark.name + "$");
    std::vector<HistorySample> marks;
    const HistoryReply found = source.client->request(find);
    for (const auto& o : found.objects()) {
        HistoryRequest rq = cpm::HistoryClient::make(cpm::history::Kind::range, "", "");
        rq.oid(o.oid());
        rq.t0(0);
        rq.t1(uint64_t(INT64_MAX));
        rq.by("data");
        rq.limit(100000);
        const HistoryReply reply = source.client->request(rq);
        if (reply.status() != "ok" && reply.status() != "partial" && reply.status() != "not_found") {
            std::fprintf(stderr, "%s: %s %s\n", command.c_str(), reply.status().c_str(), reply.error().c_str());
            return 1;
        }
        marks.insert(marks.end(), reply.samples().begin(), reply.samples().end());
    }
    std::stable_sort(marks.begin(), marks.end(), [](const HistorySample& a, const HistorySample& b) { return a.data_ns() < b.data_ns(); });
    if (marks.empty() && !parsed.has("--json")) std::printf("no bookmarks%s\n", file.empty() ? " held" : (" in " + file).c_str());
    const auto& types = source.decoder();
    for (const auto& s : marks) {
        const auto b = types.decode("Bookmark", s.payload());
        const std::string text = b ? b->value("text", "") : "?", who = b ? b->value("source", "") : "?";
        if (parsed.has("--json")) {
            std::printf("%s\n", nlohmann::json{{"data_ns", s.data_ns()}, {"commit_ns", s.commit_ns()}, {"text", text}, {"source", who}}.dump().c_str());
        } else {
            std::printf("%s  %-16s %s\n", cpm::cli::format_time(s.data_ns(), 3).c_str(), who.c_str(), text.c_str());
        }
    }
    return 0;
}

/// `cpm history save NAME [--before 30s] [--after 10s] [--topics A,B]`: the dash-cam. The live
/// service writes what it holds of the last --before and what comes in the next --after into
/// a new recording NAME in its save folder, going on meanwhile.
int save_command(const std::vector<std::string>& args, const std::string& file)
{
    const std::string command = "cpm history save";
    if (!file.empty()) throw UsageError(command + ": the live service saves; a recording (--file) is copied with export --mcap|--sqlite OUT");
    if (args.empty() || args[0].rfind("--", 0) == 0) throw UsageError(command + ": which file? cpm history save NAME [flags] (.mcap: MCAP, else SQLite)");
    const std::string name = args[0];
    auto parsed = cpm::cli::parse_flags(std::vector<std::string>(args.begin() + 1, args.end()),
                                        {{"--before", true}, {"--after", true}, {"--topics", true}, {"--json", false}}, command);
    if (name.find('/') != std::string::npos) {
        throw UsageError(command + ": " + name + ": a file name; the service writes it into its save folder (cpm_history --save-dir)");
    }
    const uint64_t before = cpm::cli::parse_duration("--before", parsed.get("--before", "30s"));
    const uint64_t after = cpm::cli::parse_duration("--after", parsed.get("--after", "10s"));
    if (after > 60'000'000'000ull) throw UsageError(command + ": --after is at most 60s");
    HistoryRequest rq = cpm::HistoryClient::make(cpm::history::Kind::save, "", "");
    rq.file(name);
    rq.t0(before);
    rq.t1(after);
    rq.timeout_ns(after + 10'000'000'000ull);  // the reply comes once the span after now has passed
    std::stringstream topics(parsed.get("--topics"));
    for (std::string t; std::getline(topics, t, ',');) {
        if (!t.empty()) rq.objects().push_back(t);
    }
    cpm::HistoryClient client(client_participant());
    const HistoryReply reply = client.request(rq);
    if (parsed.has("--json")) {
        std::printf("%s\n", nlohmann::json{{"status", reply.status()}, {"error", reply.error()}, {"file", reply.file()},
                                           {"samples", reply.saved_samples()}, {"objects", reply.saved_objects()},
                                           {"from_ns", reply.saved_from_ns()}, {"to_ns", reply.saved_to_ns()}}
                                 .dump()
                                 .c_str());
    }
    if (reply.status() != "ok") {
        std::fprintf(stderr, "%s: %s%s\n", command.c_str(), reply.error().c_str(),
                     reply.file().empty() ? "" : ("; " + reply.file() + " holds what was written").c_str());
        return 1;
    }
    if (!parsed.has("--json")) {
        std::printf("%s: %llu samples of %llu objects, data times %s to %s\n", reply.file().c_str(), (unsigned long long)reply.saved_samples(),
                    (unsigned long long)reply.saved_objects(), cpm::cli::format_time(reply.saved_from_ns(), 3).c_str(),
                    cpm::cli::format_time(reply.saved_to_ns(), 3).c_str());
    }
    return 0;
}

/// The keys of every instance of `topic` the source holds.
std::vector<std::string> keys_of(const Source& source, const std::string& topic)
{
    HistoryRequest rq = cpm::HistoryClient::make(cpm::history::Kind::search, "", "");
    rq.name_regex("^" + std::regex_replace(topic, std::regex(R"([.^$|()\[\]{}*+?\\])"), R"(\$&)") + "(/|$)");
    const HistoryReply found = source.client->request(rq);
    std::vector<std::string> keys;
    for (const auto& o : found.objects()) {
        if (!o.is_process() && o.topic() == topic) keys.push_back(o.key());
    }
    return keys;
}

int export_command(const std::vector<std::string>& args, const std::string& file)
{
    const std::string command = "cpm history export";
    auto parsed = cpm::cli::parse_flags(args, {{"--topic", true}, {"--key", true}, {"--from", true}, {"--to", true}, {"--csv", false},
                                               {"--mcap", true}, {"--sqlite", true}, {"--topics", true}, {"--by", true}, {"--foxglove-3d", false}},
                                        command);
    if (parsed.has("--mcap") || parsed.has("--sqlite")) return export_recording_command(parsed, file, command);
    for (const char* f : {"--topics", "--by", "--foxglove-3d"}) {
        if (parsed.has(f)) throw UsageError(command + ": " + f + " goes with --mcap or --sqlite");
    }
    if (!parsed.has("--topic")) throw UsageError(command + ": --topic NAME is required");
    if (!parsed.has("--csv")) throw UsageError(command + ": which format? --csv (with --topic), or --mcap OUT or --sqlite OUT (with --file)");
    const Source source = open_source(file, command);
    const uint64_t from = parsed.has("--from") ? source.time("--from", parsed.get("--from")) : 0;
    const uint64_t to = parsed.has("--to") ? source.time("--to", parsed.get("--to")) : uint64_t(INT64_MAX);
    if (to < from) throw UsageError(command + ": --to is before --from");
    const std::string topic = parsed.get("--topic");
    const std::vector<std::string> keys = parsed.has("--key") ? std::vector<std::string>{parsed.get("--key")} : keys_of(source, topic);
    if (keys.empty()) {
        std::fprintf(stderr, "%s: no object of topic '%s'%s\n", command.c_str(), topic.c_str(), file.empty() ? "" : (" in " + file).c_str());
        return 1;
    }
    struct Row
    {
        uint64_t commit;
        std::vector<std::string> cells;
    };
    std::vector<Row> rows;
    std::vector<std::string> columns;
    for (const auto& key : keys) {
        for (uint64_t t0 = from;;) {  // a page of range at a time
            HistoryRequest rq = cpm::HistoryClient::make(cpm::history::Kind::range, topic, key, 0, cpm::history::By::commit);
            rq.t0(t0);
            rq.t1(to);
            rq.limit(100000);
            const HistoryReply reply = source.client->request(rq);
            // partial: the live window dropped the oldest; export writes what is held, as a recording would.
            if (reply.status() != "ok" && reply.status() != "partial" && reply.status() != "not_found" && reply.status() != "not_yet" &&
                reply.status() != "evicted") {
                std::fprintf(stderr, "%s: %s%s%s: %s %s\n", command.c_str(), topic.c_str(), key.empty() ? "" : "/", key.c_str(), reply.status().c_str(),
                             reply.error().c_str());
                return 1;
            }
            const HistoryObject* o = reply.objects().empty() ? nullptr : &reply.objects()[0];
            for (const auto& s : reply.samples()) {
                const auto j = cpm::rtdb::sample_json(s, o, &source.decoder());
                if (!j.contains("data")) {
                    std::fprintf(stderr, "%s: %s is of type %s, which cpm cannot decode: no fields to export\n", command.c_str(), topic.c_str(),
                                 o ? o->type_name().c_str() : "?");
                    return 1;
                }
                std::vector<std::string> cells{std::to_string(s.commit_ns()), std::to_string(s.data_ns()), std::to_string(s.valid_after_ns()), key};
                const auto fields = cpm::rtdb::csv::flatten(j["data"], source.decoder().field_paths(o->type_name()));
                if (columns.empty()) {
                    columns = cpm::rtdb::csv::time_columns();
                    for (const auto& f : fields) columns.push_back(f.first);
                }
                for (const auto& f : fields) cells.push_back(f.second);
                rows.push_back({s.commit_ns(), std::move(cells)});
            }
            if (!reply.truncated() || reply.samples().empty()) break;
            t0 = reply.samples().back().commit_ns() + 1;
        }
    }
    std::stable_sort(rows.begin(), rows.end(), [](const Row& a, const Row& b) { return a.commit < b.commit; });
    if (columns.empty()) {
        std::fprintf(stderr, "%s: no samples of %s in the span asked for\n", command.c_str(), topic.c_str());
        return 1;
    }
    std::fputs(cpm::rtdb::csv::line(columns).c_str(), stdout);
    for (const auto& r : rows) std::fputs(cpm::rtdb::csv::line(r.cells).c_str(), stdout);
    return 0;
}

int history_verb(const std::vector<std::string>& all)
{
    // --file FILE may come before the verb or among its flags.
    std::vector<std::string> args;
    std::string file;
    for (size_t i = 0; i < all.size(); ++i) {
        if (all[i] == "--file" || all[i].rfind("--file=", 0) == 0) {
            // Given again: the files of one recording (a split one), in the order given.
            if (all[i] == "--file" && i + 1 >= all.size()) throw UsageError("cpm history: --file needs a value (a recording.db)");
            const std::string one = all[i] == "--file" ? all[++i] : all[i].substr(7);
            if (one.empty() || one.find('\n') != std::string::npos) throw UsageError("cpm history: --file needs a value (a recording.db)");
            file += (file.empty() ? "" : "\n") + one;
        } else {
            args.push_back(all[i]);
        }
    }
    if (args.empty() || args[0].rfind("--", 0) == 0) throw UsageError("cpm history: which query? (see cpm history --help)");
    if (args[0] == "export") return export_command(std::vector<std::string>(args.begin() + 1, args.end()), file);
    if (args[0] == "save") return save_command(std::vector<std::string>(args.begin() + 1, args.end()), file);
    if (args[0] == "marks") return marks_command(std::vector<std::string>(args.begin() + 1, args.end()), file);
    if (args[0] == "diff") return diff_command(std::vector<std::string>(args.begin() + 1, args.end()), file);
    return history_command(args[0], std::vector<std::string>(args.begin() + 1, args.end()), file);
}

}  // namespace

std::vector<Command> history_commands()
{
    return {{.group = "history", .verb = "",
             .summary = "ask the history service about the recent past: list, search, latest, at, older, younger, range, "
                        "wait, successor, snapshot, changes, wait-object, marks; save (the dash-cam), export (CSV, MCAP, SQLite), diff (two runs)",
             .help = kHistoryHelp, .run = history_verb},
            {.group = "dump", .verb = "", .summary = "one table of every object the history service holds", .help = kDumpHelp, .run = dump_command}};
}

}  // namespace cpm::tools
