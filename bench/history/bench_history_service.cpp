// bench_history_service: cpm_history over DDS, in one run:
//  1. ingest: 100 vehicles' VehicleState at 100 Hz each (10,000 samples/s) for 3 s, then
//     rising rates until samples are lost; judged on the rate actually written and committed
//     (a writer that cannot keep up writes less than the nominal rate);
//  2. resident memory of the service per stored sample beyond its payload: all growth, and the
//     slope over the ends of the rates it kept up with (the target's figure: what one more
//     sample costs);
//  3. query round trip (`at` through cpm::HistoryClient) against a plain request/reply
//     ping-pong of the same types and sizes (an echo process on the next domain answering each
//     request with a reply of one stored sample's size, no store behind it), each with one
//     client of its own, in interleaved blocks; p50/p99.
//
//   bench_history_service [--domain 212] [--seconds 3]
#include "bench_common.hpp"
#include "history_load.hpp"

#include <cpm/AsyncReader.hpp>
#include <cpm/CommandLine.hpp>
#include <cpm/HistoryClient.hpp>
#include <cpm/Participant.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/stamp_message.hpp>

#include <HistoryStatus.h>
#include <VehicleState.h>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <memory>
#include <thread>

namespace {

using Clock = std::chrono::steady_clock;

cpm::ParticipantOptions options_for(int domain, bool shm) { return bench::history_bench_options(domain, shm, "bench_history"); }

/// The echo: answers every HistoryRequest with a HistoryReply holding one sample of the
/// service's size (150-byte payload) and one object info, as the service's `at` does.
int echo(int domain)
{
    cpm::Participant p(options_for(domain, true));
    cpm::WriterOptions wo;
    wo.reliable = true;
    wo.history_depth = 64;
    wo.transient_local = true;
    cpm::Writer<HistoryReply> replies(p, "historyReply", wo);
    HistoryReply proto;
    proto.status("ok");
    HistorySample s;
    s.payload(std::vector<uint8_t>(150, 7));
    s.status("ok");
    proto.samples().push_back(s);
    HistoryObject o;
    o.name("vehicleState/42");
    o.topic("vehicleState");
    o.key("42");
    o.type_name("VehicleState");
    o.creator("bench_history");
    proto.objects().push_back(o);
    cpm::ReaderOptions ro;
    ro.reliable = true;
    ro.keep_all = true;
    cpm::AsyncReader<HistoryRequest> requests(
        [&](std::vector<HistoryRequest>& batch) {
            for (auto& rq : batch) {
                HistoryReply r = proto;
                r.client_id(rq.client_id());
                r.request_id(rq.request_id());
                cpm::stamp_message(r, cpm::get_time_ns(), 0);
                (void)replies.write(r);
            }
        },
        p, "historyRequest", ro);
    std::signal(SIGTERM, [](int) { std::_Exit(0); });
    for (;;) std::this_thread::sleep_for(std::chrono::seconds(1));
}

long rss_kb(int pid)
{
    std::ifstream in("/proc/" + std::to_string(pid) + "/status");
    for (std::string line; std::getline(in, line);) {
        if (line.rfind("VmRSS:", 0) == 0) return std::stol(line.substr(6));
    }
    return -1;
}

std::vector<double> round_trips(cpm::HistoryClient& client, int n)
{
    std::vector<double> us;
    const uint64_t now = cpm::get_time_ns();
    for (int i = 0; i < n; ++i) {
        const auto t0 = Clock::now();
        auto r = client.at("vehicleState", std::to_string(i % 100), now);
        const auto t1 = Clock::now();
        if (r.samples().size() != 1) {
            std::fprintf(stderr, "bench_history_service: query %d answered %s\n", i, r.status().c_str());
            continue;
        }
        if (i >= 50) us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
    }
    return us;
}

const char* kHelp =
    "usage: bench_history_service [--domain 212] [--seconds 3]\n"
    "cpm_history over DDS: ingest without loss at rising rates, memory per stored sample, and the `at`\n"
    "round trip beside a plain request/reply ping-pong; uses domains D and D+1.\n"
    "  --seconds S  per rate\n"
    "(--echo 1: the ping-pong's echo process it starts itself)\n";

int run(int argc, char** argv)
{
    const auto flags = cpm::cli::parse_flags(argc, argv, {{"--domain", true}, {"--seconds", true}, {"--echo", true}}, "bench_history_service");
    const bool echo_role = flags.get("--echo") == "1";
    const int domain = int(cpm::cli::parse_integer("--domain", flags.get("--domain", "212"), 0, echo_role ? 232 : 231));
    if (echo_role) return echo(domain);
    const double seconds = cpm::cli::parse_number("--seconds", flags.get("--seconds", "3"), 0.1, 86400);
    bench::print_machine("bench_history_service: cpm_history on domain " + std::to_string(domain) + ", " + flags.get("--seconds", "3") +
                         " s per rate");
    const std::vector<std::string> env{"CPM_DOMAIN_ID=" + std::to_string(domain)};
    auto service = bench::spawn({cpm::sibling_executable("cpm_history"), "--window", "120s", "--max-bytes-total",
                                      "4294967296", "--max-bytes-per-topic", "4294967296"},
                                     env, "/tmp/bench_history_service.out", "/tmp/bench_history_service.err");
    // The client talks UDP loopback (a restarted service may reuse a shared-memory port);
    // the writer, like a vehicle, uses shared memory.
    cpm::Participant client_participant(options_for(domain, false));
    cpm::Participant writer_participant(options_for(domain, true));
    auto writer = bench::vehicle_state_writer(writer_participant);
    auto client_owner = std::make_unique<cpm::HistoryClient>(client_participant, std::chrono::milliseconds(10000));
    cpm::HistoryClient& client = *client_owner;
    if (!writer.wait_for_matched(1, std::chrono::milliseconds(10000))) {
        // The service subscribes when it discovers the topic: write once so it does.
        std::fprintf(stderr, "bench_history_service: the service did not subscribe\n");
    }
    double tag = 0;
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    const long rss_before = rss_kb(service.pid());
    const uint64_t before = 0;
    // What the service holds (samples, payload bytes) and its resident size, after each rate.
    struct Held
    {
        uint64_t samples = 0, bytes = 0;
        long rss_kb = 0;
    };
    auto held_now = [&] {
        HistoryRequest rq = cpm::HistoryClient::make(cpm::history::Kind::search, "", "");
        rq.name_regex("^vehicleState/");
        Held h;
        const HistoryReply reply = client.request(rq);  // a named reply: a temporary would die before the loop
        for (const auto& o : reply.objects()) {
            h.samples += o.samples_held();
            h.bytes += o.bytes_held();
        }
        h.rss_kb = rss_kb(service.pid());
        return h;
    };
    std::vector<Held> steps;

    std::printf("\ningest (100 vehicles, VehicleState, reliable writer, depth 100 per vehicle)\n");
    std::printf("%12s %10s %10s %8s %14s\n", "nominal /s", "written", "committed", "lost", "committed /s");
    uint64_t written_total = 0;
    double best_clean = 0;
    uint64_t base = before;
    for (double rate : {10'000.0, 15'000.0, 20'000.0, 30'000.0, 40'000.0, 60'000.0, 80'000.0}) {
        const uint64_t w = bench::write_at(writer, rate, seconds, tag);
        writer.wait_for_acknowledgments(std::chrono::milliseconds(5000));
        std::this_thread::sleep_for(std::chrono::milliseconds(300));
        const uint64_t c = bench::committed(client) - base;
        base += c;
        written_total += w;
        const double achieved = double(c) / seconds;
        std::printf("%12.0f %10llu %10llu %8lld %14.0f\n", rate, (unsigned long long)w, (unsigned long long)c, (long long)w - (long long)c,
                    achieved);
        if (c >= w) steps.push_back(held_now());  // the memory figure: rates it kept up with (an overload's backlog is not held samples)
        if (c >= w) best_clean = achieved;
        else break;
    }
    std::printf("highest rate written and committed with none lost: %.0f samples/s (target >= 20000: %s)\n", best_clean,
                best_clean >= 20000 ? "met" : "not met");

    // Memory: the whole growth since before ingest (fixed costs such as DDS buffers and
    // thread arenas included), and the marginal cost between the first two rates' ends.
    const Held last = held_now();
    std::printf("\nmemory: %llu samples held, %llu payload bytes; service RSS %ld -> %ld KiB: %.1f bytes per sample beyond "
                "its payload, all growth counted (fixed DDS buffers and thread arenas included)\n",
                (unsigned long long)last.samples, (unsigned long long)last.bytes, rss_before, last.rss_kb,
                last.samples ? (double(last.rss_kb - rss_before) * 1024.0 - double(last.bytes)) / double(last.samples) : 0.0);
    if (steps.size() >= 2 && steps.back().samples > steps.front().samples) {
        // What one more held sample costs: the least-squares slope of (RSS - payload) against
        // samples held over the end of every rate it kept up with, not one pair of them picked.
        double ms = 0, mc = 0;
        for (const auto& h : steps) {
            ms += double(h.samples) / double(steps.size());
            mc += (double(h.rss_kb) * 1024.0 - double(h.bytes)) / double(steps.size());
        }
        double sxy = 0, sxx = 0;
        for (const auto& h : steps) {
            const double dx = double(h.samples) - ms;
            sxy += dx * ((double(h.rss_kb) * 1024.0 - double(h.bytes)) - mc);
            sxx += dx * dx;
        }
        const double per_sample = sxy / sxx;
        std::printf("memory, per sample: %.1f bytes beyond its payload, the slope over the ends of the %zu rates it kept up with "
                    "(%llu to %llu samples held; the target's figure, <= 64: %s)\n",
                    per_sample, steps.size(), (unsigned long long)steps.front().samples, (unsigned long long)steps.back().samples,
                    per_sample <= 64 ? "met" : "not met");
        bench::record({"history_service", "RSS per held sample beyond its payload (slope over the rates kept up with)", "bytes", per_sample, "", 0,
                       "<= 64 bytes", per_sample <= 64 ? 1 : 0});
        bench::record({"history_service", "RSS growth per held sample beyond its payload (all growth, fixed costs included)", "bytes",
                       last.samples ? (double(last.rss_kb - rss_before) * 1024.0 - double(last.bytes)) / double(last.samples) : 0.0, "", 0,
                       "", -1});
    }

    // The echo answers on the next domain, so both run at once and alternate in blocks; each
    // side has one client (one reliable reply reader), none left attached from the ingest.
    client_owner.reset();
    auto echo_process = bench::spawn_self({"--echo", "1", "--domain", std::to_string(domain + 1)});
    cpm::Participant echo_participant(options_for(domain + 1, false));
    cpm::HistoryClient service_client(client_participant, std::chrono::milliseconds(10000));
    cpm::HistoryClient echo_client(echo_participant, std::chrono::milliseconds(10000));
    constexpr int kBlocks = 10, kPerBlock = 200;
    std::printf("\nquery round trip: `at` through cpm::HistoryClient vs plain request/reply ping-pong, %d blocks of %d "
                "each, alternating\n", kBlocks, kPerBlock);
    std::vector<double> service_us, echo_us;
    for (int b = 0; b < kBlocks; ++b) {
        for (auto& x : round_trips(service_client, kPerBlock + 50)) service_us.push_back(x);
        for (auto& x : round_trips(echo_client, kPerBlock + 50)) echo_us.push_back(x);
    }
    bench::print_header("round trip");
    const auto service_stats = bench::stats_of(service_us), echo_stats = bench::stats_of(echo_us);
    bench::print_row("cpm_history at", service_stats);
    bench::print_row("plain ping-pong", echo_stats);
    bench::print_ratio("cpm_history / ping-pong (target <= 1.5)", service_stats, echo_stats);
    bench::record_latency("history_service", "at round trip", service_stats, "plain request/reply ping-pong", echo_stats, 1.5);
    service.signal(SIGTERM);
    bench::wait_child(service, 10);
    echo_process.signal(SIGTERM);
    bench::wait_child(echo_process, 10);
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "bench_history_service", kHelp, run); }
