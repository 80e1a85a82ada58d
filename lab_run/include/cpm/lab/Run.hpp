#pragma once
// cpm::lab::run_lab — a scenario run as one thing: its processes started and supervised, the
// lab clock driven, everything recorded, and everything stopped in order at the end.
//
// The run's folder (runs/<name>-<UTC time>/ or the one given) gets one <process>.log per
// process (its stdout and stderr), the recording (recording.db) and summary.json.
#include <cpm/lab/Scenario.hpp>

#include <nlohmann/json.hpp>

#include <cstdint>
#include <cstdio>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace cpm::lab {

struct RunOptions
{
    std::string out_dir;                      ///< "": runs/<name>-<UTC time> under the working folder
    std::optional<uint64_t> duration_ns;      ///< overrides the scenario's
    std::optional<TimeMode> time;             ///< overrides the scenario's
    std::optional<int> domain;                ///< overrides the scenario's (and CPM_DOMAIN_ID)
    std::string bin_dir;                      ///< where cpm's programs are
    std::FILE* progress = nullptr;            ///< the progress line; a terminal gets one line redrawn
    std::function<bool()> stop = [] { return false; };  ///< Ctrl-C: ends the run cleanly
};

/// How one process ended.
struct ProcessEnd
{
    std::string name;
    std::string how;        ///< "exited with code 0", "killed by SIGSEGV"
    bool failed = false;    ///< it died during the run, or ended badly when stopped
    int restarts = 0;
    std::string last_lines; ///< the end of its log when it failed
};

struct RunResult
{
    std::string dir;
    bool ok = false;
    bool interrupted = false;           ///< stopped by RunOptions::stop
    uint64_t lab_time_ns = 0;           ///< how far the lab clock got
    double real_seconds = 0;            ///< the whole run: processes started, clock, stopped
    /// A simulated run: the real seconds its clock stepped (first step to the last), the lab
    /// time it covered per real second being lab_time_ns / 1e9 / clock_seconds; 0 in real time.
    double clock_seconds = 0;
    std::vector<ProcessEnd> processes;
    std::string error;                  ///< why the run ended early ("" when it ran its time)
    /// Across hosts: each host's clock against the run's own (offset and round trip, ns), and
    /// whether it was lost during the run.
    struct Host
    {
        std::string name, address;
        int64_t clock_offset_ns = 0, rtt_ns = 0;
        bool lost = false;
    };
    std::vector<Host> hosts;
    /// Per topic, the samples the recorder never received (gaps in their writers' numbering):
    /// it could not keep up. Also in summary.json (recording.lost_by_topic) and the report.
    std::map<std::string, uint64_t> recording_lost_by_topic;
};

/// What a recording misses, as the run and its report say it ("" when nothing):
/// "N samples never reached the recorder (topic n, …; it could not keep up)".
std::string recording_loss(const std::map<std::string, uint64_t>& lost_by_topic);
/// The same from summary.json's recording block (recording.lost_by_topic).
std::map<std::string, uint64_t> recording_lost_by_topic(const nlohmann::json& recording);

/// Runs the scenario. Throws ScenarioError for a missing program, a host that cannot be reached,
/// runs another cpm or whose clock is off by more than max_clock_offset, and cpm::Error when the
/// run's folder cannot be made (each before anything starts anywhere).
RunResult run_lab(const Scenario& scenario, const RunOptions& options);

}  // namespace cpm::lab
