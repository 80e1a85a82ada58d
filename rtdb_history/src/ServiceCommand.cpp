#include <cpm/rtdb/ServiceCommand.hpp>

#include <cpm/rtdb/IdlDecoder.hpp>
#include <cpm/timer_ids.hpp>
#include <cpm/topics.hpp>

#include <algorithm>
#include <filesystem>

#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdio>
#include <memory>
#include <regex>
#include <thread>

namespace cpm::rtdb {

using cli::UsageError;

SaveTrigger parse_save_trigger(const std::string& text)
{
    SaveTrigger t{.text = text};
    const auto eq = text.find('=');
    t.topic = text.substr(0, eq);
    const auto bad = [&](const std::string& why) {
        return UsageError("cpm_history: --save-on '" + text + "': " + why + " (TOPIC, or TOPIC=FIELD==VALUE, e.g. fsmStatus=state_type==Emergency)");
    };
    if (t.topic.empty()) throw bad("no topic");
    if (eq == std::string::npos) return t;
    const std::string filter = text.substr(eq + 1);
    size_t op = filter.find("==");
    t.equal = op != std::string::npos;
    if (!t.equal) op = filter.find("!=");
    if (op == std::string::npos) throw bad("the filter '" + filter + "' has no == or !=");
    t.field = filter.substr(0, op);
    t.value = filter.substr(op + 2);
    if (t.field.empty() || t.field.find_first_of(" =!") != std::string::npos) throw bad("the filter's field '" + t.field + "' is no field path");
    // A topic of the lab's table has a known type: its field must be one of the type's.
    if (const TopicSpec* spec = topics::find(t.topic)) {
        if (const IdlDecoder* types = IdlDecoder::lab_types()) {
            const auto fields = types->field_paths(spec->type_name);
            if (!fields.empty() && std::find(fields.begin(), fields.end(), t.field) == fields.end()) {
                std::string known;
                for (const auto& f : fields) known += (known.empty() ? "" : ", ") + f;
                throw bad(std::string(spec->type_name) + " has no field '" + t.field + "' (it has " + known + ")");
            }
        }
    }
    return t;
}

const std::vector<cli::FlagSpec>& service_flags()
{
    static const std::vector<cli::FlagSpec> flags{{"--include", true, true},
                                                  {"--exclude", true, true},
                                                  {"--window", true},
                                                  {"--topic-window", true, true},
                                                  {"--max-bytes-total", true},
                                                  {"--max-bytes", true},
                                                  {"--max-bytes-per-topic", true},
                                                  {"--status-period", true},
                                                  {"--record", true},
                                                  {"--record-max-bytes", true},
                                                  {"--record-format", true},
                                                  {"--foxglove-3d", false},
                                                  {"--record-split", true},
                                                  {"--record-max", true},
                                                  {"--save-dir", true},
                                                  {"--save-on", true, true},
                                                  {"--save-before", true},
                                                  {"--save-after", true},
                                                  {"--save-format", true},
                                                  {"--record-name", true},
                                                  {"--simulated-clock", false}};
    return flags;
}

ServiceCommand read_service_flags(const cli::ParsedArgs& parsed)
{
    ServiceCommand c;
    ServiceOptions& options = c.options;
    options.include = parsed.all("--include");
    options.exclude = parsed.all("--exclude");
    for (const auto& [flag, patterns] : {std::pair{"--include", options.include}, std::pair{"--exclude", options.exclude}}) {
        for (const auto& p : patterns) {
            try {
                std::regex check(p);
            } catch (const std::regex_error& e) {
                throw UsageError(std::string(flag) + " '" + p + "' is not a regular expression: " + e.what());
            }
        }
    }
    options.window_ns = cli::parse_duration("--window", parsed.get("--window", "10s"));
    if (options.window_ns == 0) throw UsageError("--window must be longer than 0");
    for (const auto& item : parsed.all("--topic-window")) {
        const auto eq = item.find('=');
        if (eq == std::string::npos || eq == 0) {
            throw UsageError("cpm_history: --topic-window '" + item + "': expected TOPIC=DURATION (e.g. vehicleState=60s)");
        }
        const uint64_t w = cli::parse_duration("--topic-window", item.substr(eq + 1));
        if (w == 0) throw UsageError("cpm_history: --topic-window '" + item + "': the window must be longer than 0");
        options.topic_windows_ns[item.substr(0, eq)] = w;
    }
    if (parsed.has("--max-bytes") && parsed.has("--max-bytes-total"))
        throw UsageError("cpm_history: --max-bytes is the older name of --max-bytes-total; give one");
    const char* total_flag = parsed.has("--max-bytes") ? "--max-bytes" : "--max-bytes-total";
    options.max_bytes_total = static_cast<uint64_t>(cli::parse_integer(total_flag, parsed.get(total_flag, "536870912"), 1024, 1LL << 40));
    options.max_bytes_per_topic = static_cast<uint64_t>(
        cli::parse_integer("--max-bytes-per-topic", parsed.get("--max-bytes-per-topic", "134217728"), 1024, 1LL << 40));
    options.status_period_ns = cli::parse_duration("--status-period", parsed.get("--status-period", "1s"));
    if (parsed.has("--save-dir")) {
        c.options.save_dir = parsed.get("--save-dir");
        if (!std::filesystem::is_directory(c.options.save_dir)) {
            throw UsageError("cpm_history: --save-dir " + c.options.save_dir + ": no such folder");
        }
    }
    for (const auto& t : parsed.all("--save-on")) options.save_on.push_back(parse_save_trigger(t));
    if (options.save_on.empty()) {
        for (const char* f : {"--save-before", "--save-after", "--save-format"}) {
            if (parsed.has(f)) throw UsageError(std::string("cpm_history: ") + f + " goes with --save-on");
        }
    }
    options.save_before_ns = cli::parse_duration("--save-before", parsed.get("--save-before", "30s"));
    options.save_after_ns = cli::parse_duration("--save-after", parsed.get("--save-after", "10s"));
    if (parsed.has("--simulated-clock")) options.clock_node = timer_ids::history;
    options.save_format = parsed.get("--save-format", "sqlite");
    if (options.save_format != "sqlite" && options.save_format != "mcap") {
        throw UsageError("cpm_history: --save-format '" + options.save_format + "': expected sqlite or mcap");
    }
    if (parsed.has("--record")) {
        c.record_path = parsed.get("--record");
        c.record.name = parsed.get("--record-name");
        c.record.format = parsed.get("--record-format");
        c.record.foxglove_3d = parsed.has("--foxglove-3d");
        if (parsed.has("--record-split")) {
            const std::string split = parsed.get("--record-split");
            if (cli::looks_like_bytes(split)) c.record.split_bytes = cli::parse_bytes("--record-split", split);
            else c.record.split_ns = cli::parse_duration("--record-split", split);
            if (c.record.split_bytes + c.record.split_ns == 0) throw UsageError("cpm_history: --record-split must be more than 0");
        }
        if (parsed.has("--record-max")) {
            if (!parsed.has("--record-split")) throw UsageError("cpm_history: --record-max goes with --record-split (it deletes the oldest files)");
            c.record.max_total_bytes = cli::parse_bytes("--record-max", parsed.get("--record-max"));
        }
        if (!c.record.format.empty() && c.record.format != "sqlite" && c.record.format != "mcap") {
            throw UsageError("cpm_history: --record-format '" + c.record.format + "': expected sqlite or mcap");
        }
        if (parsed.has("--record-max-bytes"))
            c.record.max_bytes = uint64_t(cli::parse_integer("--record-max-bytes", parsed.get("--record-max-bytes"), 65536, 1LL << 50));
    } else if (parsed.has("--record-max-bytes") || parsed.has("--record-name") || parsed.has("--record-format") || parsed.has("--foxglove-3d") ||
               parsed.has("--record-split") || parsed.has("--record-max")) {
        throw UsageError("cpm_history: --record-max-bytes, --record-name, --record-format, --foxglove-3d, --record-split and --record-max go with --record FILE");
    }
    return c;
}

int serve(ServiceCommand command, const std::function<bool()>& stop_requested)
{
    std::shared_ptr<RecordingWriter> recording;
    if (!command.record_path.empty()) {
        try {
            recording = std::make_shared<RecordingWriter>(command.record_path, command.record);
        } catch (const std::runtime_error& e) {
            throw UsageError(std::string("cpm_history: --record: ") + e.what());
        }
        command.options.sinks.push_back(recording);
    }
    int status = 0;
    const double window_s = double(command.options.window_ns) * 1e-9;
    auto service = std::make_unique<HistoryService>(std::move(command.options));
    std::fprintf(stderr, "cpm_history: recording (window %.1f s)%s%s; Ctrl-C ends\n", window_s, recording ? ", every sample also to " : "",
                 recording ? recording->path().c_str() : "");
    bool said = false;
    while (!stop_requested()) {
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
        if (recording && !said && recording->counters().failed) {
            std::fprintf(stderr, "cpm_history: %s; the live history goes on\n", recording->counters().error.c_str());
            said = true;
        }
    }
    const auto c = service->counters();
    service.reset();  // nothing more is ingested: the recording gets all there was
    nlohmann::json counts{{"topics", c.topics}, {"received", c.received}, {"dropped", c.dropped},
                          {"lost", c.lost},     {"requests", c.requests}, {"bad_requests", c.bad_requests},
                          {"lost_by_topic", c.lost_by_topic}};
    if (recording) {
        recording->close();
        const auto r = recording->counters();
        counts["recording"] = {{"file", recording->path()}, {"written", r.written}, {"dropped", r.dropped}, {"error", r.error}};
        if (r.failed) status = 1;
    }
    std::printf("%s\n", counts.dump().c_str());
    std::fflush(stdout);
    return status;
}

}  // namespace cpm::rtdb
