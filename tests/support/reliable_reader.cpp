// A test helper: a reliable, keep-all VehicleState reader in its own process that prints
// "matched" once a writer matched, then takes (and acknowledges) whatever arrives until stopped
// (SIGINT/SIGTERM end it cleanly: its shared memory goes with it).
//   reliable_reader TOPIC                (domain from CPM_DOMAIN_ID)
//   reliable_reader TOPIC --expect N     counts samples whose pose.x is their number 0, 1, 2, …:
//       once N have arrived (or nothing came for 10 s) prints one JSON line
//       {"received":…,"in_order":…,"gaps":…,"duplicates":…} and exits (0 when all N came in order)
#include <cpm/CommandLine.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/init.hpp>

#include <VehicleState.h>

#include <chrono>
#include <climits>
#include <cstdio>
#include <string>
#include <vector>

namespace {

const char* kHelp =
    "usage: reliable_reader TOPIC [--expect N]\n"
    "A reliable, keep-all VehicleState reader on TOPIC: prints \"matched\" once a writer matched, then takes\n"
    "what arrives until stopped; with --expect, until N samples came (or none for 10 s), then prints\n"
    "{\"received\",\"in_order\",\"gaps\",\"duplicates\"} and exits 0 when all N came in order.\n";

int run(int argc, char** argv)
{
    const auto args = cpm::cli::parse_args(std::vector<std::string>(argv + 1, argv + argc), {{"--expect", true}}, "reliable_reader");
    if (args.positional.size() != 1) throw cpm::cli::UsageError("reliable_reader: give one TOPIC (see --help)");
    const long long expect = args.has("--expect") ? cpm::cli::parse_integer("--expect", args.get("--expect"), 0, LLONG_MAX) : -1;
    cpm::init(argc, argv);
    cpm::cli::stop_on_signals();
    cpm::ReaderOptions options;
    options.reliable = true;
    options.keep_all = true;
    cpm::ReaderAbstract<VehicleState> reader(args.positional[0], options);
    if (!reader.wait_for_matched(1, std::chrono::seconds(20))) return 3;
    if (cpm::cli::stop_requested()) return 0;
    std::printf("matched\n");
    std::fflush(stdout);
    long long received = 0, next = 0, gaps = 0, duplicates = 0;
    auto quiet_since = std::chrono::steady_clock::now();
    while (!cpm::cli::stop_requested()) {
        if (reader.wait_for_data(std::chrono::milliseconds(100))) {
            for (const auto& s : reader.take()) {
                ++received;
                const auto n = static_cast<long long>(s.pose().x());
                if (n < next) ++duplicates;
                if (n > next) gaps += n - next;
                if (n >= next) next = n + 1;
            }
            quiet_since = std::chrono::steady_clock::now();
        }
        if (expect < 0) continue;
        if (received >= expect || std::chrono::steady_clock::now() - quiet_since > std::chrono::seconds(10)) break;
    }
    const bool in_order = received == expect && next == expect && gaps == 0 && duplicates == 0;
    std::printf("{\"received\":%lld,\"in_order\":%s,\"gaps\":%lld,\"duplicates\":%lld}\n", received, in_order ? "true" : "false", gaps,
                duplicates);
    return in_order ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "reliable_reader", kHelp, run); }
