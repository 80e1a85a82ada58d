#pragma once
// cpm_history's command line as a library: its flags read into ServiceOptions (and a recording
// to make), and the service run until a stop, with the recording closed and the counts printed.
#include <cpm/CommandLine.hpp>
#include <cpm/rtdb/HistoryService.hpp>
#include <cpm/rtdb/Recording.hpp>

#include <functional>
#include <string>
#include <vector>

namespace cpm::rtdb {

/// cpm_history's flags (besides cpm::init's).
const std::vector<cli::FlagSpec>& service_flags();

/// What cpm_history's flags ask for.
struct ServiceCommand
{
    ServiceOptions options;
    std::string record_path;  ///< --record FILE ("" for none)
    RecordingOptions record;
};

/// Reads parsed flags; throws cpm::cli::UsageError naming the flag and value (a pattern that is
/// not a regex, a zero window, --record-name without --record, ...).
ServiceCommand read_service_flags(const cli::ParsedArgs& parsed);

/// Runs the service (and its recording, when asked) until `stop_requested()`. Says on stderr
/// when the recording fails while the live history goes on. At the end the ingest stops first,
/// then the recording is closed with everything ingested, and one JSON line of counts goes to
/// stdout. Returns the exit status: 1 when the recording failed, else 0. Throws
/// cpm::cli::UsageError when the recording's file cannot be made.
int serve(ServiceCommand command, const std::function<bool()>& stop_requested);

}  // namespace cpm::rtdb
