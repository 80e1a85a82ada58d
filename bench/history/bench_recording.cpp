// bench_recording: recordings, in one run:
//  1. ingest with the recording off and on: cpm_history without and with --record (SQLite, and
//     MCAP), the same rising rates of 100 vehicles' VehicleState; the highest rate at which every
//     written sample was committed (and, when on, every committed sample reached the file).
//     Targets: >= 20,000/s with the recording on; MCAP >= SQLite.
//  1b. export of a million samples SQLite -> MCAP and MCAP -> SQLite (samples/s) and each
//     file's size per sample; loading each into a store (`at` is then the same store's).
//  2. `at` on one object: from the live store, from the recording loaded into a store, and from
//     SQLite on the recording file with a plain index on (oid, commit_ns); random times over the
//     held span, p50 of blocks; the load's own time.
//  3. the file's size per sample beyond its payload.
//  4. cpm play at rate 1: how late each sample leaves against its recorded spacing, p50/p99.
//
//   bench_recording [--domain 214] [--seconds 3]
#include "bench_common.hpp"
#include "history_load.hpp"

#include <cpm/CommandLine.hpp>
#include <cpm/Participant.hpp>
#include <cpm/percentile.hpp>
#include <cpm/rtdb/Player.hpp>
#include <cpm/rtdb/Recording.hpp>
#include <cpm/rtdb/Requests.hpp>

#include <VehicleStatePubSubTypes.h>
#include <sqlite3.h>

#include <algorithm>
#include <csignal>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <thread>
#include <unistd.h>

namespace {

using Clock = std::chrono::steady_clock;
namespace fs = std::filesystem;

cpm::ParticipantOptions options_for(int domain, bool shm) { return bench::history_bench_options(domain, shm, "bench_recording"); }

struct Ramp
{
    double best = 0;           ///< highest committed rate with none lost
    std::string rows;
};

/// The rising rates against a cpm_history with these extra arguments; `recorded` is asked, once
/// the service ended, how many samples the file holds (0: no file).
Ramp ramp(int domain, double seconds, const std::vector<std::string>& extra, const std::string& file)
{
    std::vector<std::string> argv{cpm::sibling_executable("cpm_history"), "--window", "5s", "--max-bytes-total", "4294967296",
                                  "--max-bytes-per-topic", "4294967296"};
    argv.insert(argv.end(), extra.begin(), extra.end());
    auto service = bench::spawn(argv, {"CPM_DOMAIN_ID=" + std::to_string(domain)}, "/tmp/bench_recording.out", "/tmp/bench_recording.err");
    Ramp out;
    {
        cpm::Participant client_participant(options_for(domain, false));
        cpm::Participant writer_participant(options_for(domain, true));
        auto writer = bench::vehicle_state_writer(writer_participant);
        cpm::HistoryClient client(client_participant, std::chrono::milliseconds(10000));
        if (!writer.wait_for_matched(1, std::chrono::milliseconds(10000))) std::fprintf(stderr, "bench_recording: the service did not subscribe\n");
        std::this_thread::sleep_for(std::chrono::milliseconds(500));
        double tag = 0;
        uint64_t base = 0;
        char line[160];
        for (double rate : {10'000.0, 20'000.0, 30'000.0, 40'000.0, 60'000.0}) {
            const uint64_t w = bench::write_at(writer, rate, seconds, tag);
            writer.wait_for_acknowledgments(std::chrono::milliseconds(5000));
            std::this_thread::sleep_for(std::chrono::milliseconds(300));
            const uint64_t c = bench::committed(client) - base;
            base += c;
            std::snprintf(line, sizeof line, "%12.0f %10llu %10llu %8lld %14.0f\n", rate, (unsigned long long)w, (unsigned long long)c,
                          (long long)w - (long long)c, double(c) / seconds);
            out.rows += line;
            if (c >= w) out.best = double(c) / seconds;
            else break;
        }
    }
    service.signal(SIGINT);  // the recording is closed
    bench::wait_child(service, 60);
    if (!file.empty()) {
        // Zero loss means the file holds every committed sample: the service's own count.
        std::ifstream in("/tmp/bench_recording.out");
        std::string last, line;
        while (std::getline(in, line)) last = line;
        try {
            const auto j = nlohmann::json::parse(last);
            const uint64_t received = j["received"], written = j["recording"]["written"], dropped = j["recording"]["dropped"];
            out.rows += "recording: " + std::to_string(written) + " samples in the file of " + std::to_string(received) +
                        " received, " + std::to_string(dropped) + " dropped\n";
            if (dropped > 0) out.best = 0;
        } catch (const std::exception&) {
            out.rows += "recording: the service printed no counts (" + last + ")\n";
            out.best = 0;
        }
    }
    return out;
}

const char* kHelp =
    "usage: bench_recording [--domain 214] [--seconds 3]\n"
    "Recordings: ingest with cpm_history's --record on (SQLite, MCAP) against off, export both ways,\n"
    "`at` from a recording against the live store and SQLite, the file's size per sample, and cpm\n"
    "play's timing; uses domains D to D+3.\n"
    "  --seconds S  per rate\n";

int run(int argc, char** argv)
{
    const auto flags = cpm::cli::parse_flags(argc, argv, {{"--domain", true}, {"--seconds", true}}, "bench_recording");
    const int domain = int(cpm::cli::parse_integer("--domain", flags.get("--domain", "214"), 0, 230));
    const double seconds = cpm::cli::parse_number("--seconds", flags.get("--seconds", "3"), 0.1, 86400);
    bench::print_machine("bench_recording: domain " + std::to_string(domain) + ", " + flags.get("--seconds", "3") + " s per rate");
    const fs::path dir = fs::temp_directory_path() / ("bench_recording." + std::to_string(::getpid()));
    fs::create_directories(dir);

    // 1. Ingest, recording off and on, the same rates.
    std::printf("\ningest (100 vehicles, VehicleState, reliable writer), cpm_history without and with --record\n");
    std::printf("%12s %10s %10s %8s %14s\n", "nominal /s", "written", "committed", "lost", "committed /s");
    const Ramp off = ramp(domain, seconds, {}, "");
    std::printf("recording off:\n%s", off.rows.c_str());
    const std::string ingest_file = (dir / "ingest.db").string();
    const Ramp on = ramp(domain + 1, seconds, {"--record", ingest_file}, ingest_file);
    std::printf("recording on:\n%s", on.rows.c_str());
    std::printf("highest rate with none lost: off %.0f/s, on %.0f/s (on/off %.2f; target on >= 20000: %s)\n", off.best, on.best,
                off.best > 0 ? on.best / off.best : 0.0, on.best >= 20000 ? "met" : "not met");
    bench::record({"recording", "ingest with none lost, recording on", "samples/s", on.best, "cpm_history, recording off", off.best,
                   ">= 20000/s", int(on.best >= 20000)});
    const std::string mcap_ingest = (dir / "ingest.mcap").string();
    const Ramp on_mcap = ramp(domain + 3, seconds, {"--record", mcap_ingest}, mcap_ingest);
    std::printf("recording on, MCAP:\n%s", on_mcap.rows.c_str());
    const bool mcap_met = on_mcap.best > 0 && on_mcap.best >= on.best;
    std::printf("highest rate with none lost: MCAP %.0f/s, SQLite %.0f/s (MCAP/SQLite %.2f; target >= 1.0: %s)\n", on_mcap.best, on.best,
                on.best > 0 ? on_mcap.best / on.best : 0.0, mcap_met ? "met" : "not met");
    bench::record({"recording", "ingest with none lost, recording to MCAP", "samples/s", on_mcap.best, "recording to SQLite", on.best,
                   ">= 1.0x SQLite", int(mcap_met)});

    // 2. at: live store, loaded recording, SQLite on the file.
    using namespace cpm::rtdb;
    const std::string file = (dir / "at.db").string();
    constexpr int kObjects = 20, kPerObject = 50'000;
    Store live(StoreOptions{.default_retention = {.window_ns = uint64_t(1) << 62, .max_bytes_per_topic = 1ull << 40},
                            .max_bytes_total = 1ull << 40});
    uint64_t payload_bytes = 0;
    std::vector<Oid> oids;
    {
        RecordingWriter writer(file);
        std::vector<uint8_t> payload(150, 7);
        for (int o = 0; o < kObjects; ++o) {
            oids.push_back(live.add_object({.topic = "vehicleState", .key = std::to_string(o), .type_name = "VehicleState", .created_ts = 1}));
            writer.object_added(*live.info(oids.back()));
        }
        for (uint64_t i = 0; i < kPerObject; ++i) {
            for (int o = 0; o < kObjects; ++o) {
                const uint64_t now = 1'000'000'000ull + i * 20'000'000ull + uint64_t(o) * 1000;
                Incoming in{now - 100, now, now - 50, payload.data(), payload.size(), 0};
                const uint64_t c = live.commit(oids[o], in, now);
                writer.sample_committed(oids[o], in, c);
                payload_bytes += payload.size();
            }
        }
        writer.close();
    }
    const uint64_t samples = uint64_t(kObjects) * kPerObject;
    const auto load_t0 = Clock::now();
    const LoadedRecording rec = load_recording(file);
    const double load_s = std::chrono::duration<double>(Clock::now() - load_t0).count();
    std::printf("\nat on one object (%d objects x %d samples of 150 bytes, %llu in all)\n", kObjects, kPerObject, (unsigned long long)samples);
    std::printf("loading the recording into a store: %.2f s (%.0f samples/s)\n", load_s, double(samples) / load_s);

    sqlite3* db = nullptr;
    sqlite3_open_v2(file.c_str(), &db, SQLITE_OPEN_READONLY, nullptr);
    sqlite3_stmt* q = nullptr;
    sqlite3_prepare_v2(db, "SELECT commit_ns, data_ns, valid_after_ns, source_ns, payload FROM samples WHERE oid = ? AND commit_ns <= ?"
                           " ORDER BY commit_ns DESC LIMIT 1", -1, &q, nullptr);
    std::mt19937_64 rng(1);
    const uint64_t span = uint64_t(kPerObject) * 20'000'000ull;
    constexpr int kBlock = 2000, kBlocks = 15;
    std::vector<double> t_live, t_loaded, t_sql;
    uint64_t sink = 0;
    for (int b = 0; b < kBlocks; ++b) {
        std::vector<std::pair<Oid, uint64_t>> asks(kBlock);
        for (auto& a : asks) a = {oids[rng() % kObjects], 1'000'000'000ull + rng() % span};
        auto time_block = [&](auto&& f) {
            const auto t0 = Clock::now();
            for (const auto& [oid, t] : asks) f(oid, t);
            return std::chrono::duration<double, std::nano>(Clock::now() - t0).count() / kBlock;
        };
        t_live.push_back(time_block([&](Oid o, uint64_t t) { sink += live.at(o, t).sample.commit_ns; }));
        t_loaded.push_back(time_block([&](Oid o, uint64_t t) { sink += rec.store->at(o, t).sample.commit_ns; }));
        t_sql.push_back(time_block([&](Oid o, uint64_t t) {
            sqlite3_bind_int64(q, 1, int64_t(o));
            sqlite3_bind_int64(q, 2, int64_t(t));
            if (sqlite3_step(q) == SQLITE_ROW) {
                std::vector<uint8_t> copy(static_cast<const uint8_t*>(sqlite3_column_blob(q, 4)),
                                          static_cast<const uint8_t*>(sqlite3_column_blob(q, 4)) + sqlite3_column_bytes(q, 4));
                sink += uint64_t(sqlite3_column_int64(q, 0)) + copy.size();
            }
            sqlite3_reset(q);
        }));
    }
    sqlite3_finalize(q);
    sqlite3_close(db);
    const double live_ns = cpm::percentile(t_live, 0.5), loaded_ns = cpm::percentile(t_loaded, 0.5), sql_ns = cpm::percentile(t_sql, 0.5);
    std::printf("%-44s %10.0f ns\n", "live store (copied answer)", live_ns);
    std::printf("%-44s %10.0f ns (%.2fx the live store)\n", "recording loaded into a store (copied answer)", loaded_ns, loaded_ns / live_ns);
    std::printf("%-44s %10.0f ns (%.1fx the loaded store)\n", "SQLite on the file, index (oid, commit_ns)", sql_ns, sql_ns / loaded_ns);
    bench::record({"recording", "at from a loaded recording (copied answer)", "ns", loaded_ns, "SQLite on the file, index (oid, commit_ns)", sql_ns});
    std::printf("(checksum %llu)\n", (unsigned long long)(sink & 0xff));

    // 1b. Export both ways, each file's size, each loaded into a store.
    {
        const std::string mcap = (dir / "at.mcap").string(), back = (dir / "back.db").string();
        const auto t0 = Clock::now();
        (void)export_recording(file, mcap, {});
        const double to_mcap_s = std::chrono::duration<double>(Clock::now() - t0).count();
        const auto t1 = Clock::now();
        (void)export_recording(mcap, back, {});
        const double to_sqlite_s = std::chrono::duration<double>(Clock::now() - t1).count();
        // A copy: the export above read the MCAP file once, and a process reads a file once.
        const std::string fresh = (dir / "fresh.mcap").string();
        fs::copy_file(mcap, fresh);
        const auto t2 = Clock::now();
        const LoadedRecording from_mcap = load_recording(fresh);
        const double load_mcap_s = std::chrono::duration<double>(Clock::now() - t2).count();
        const auto size_of = [&](const std::string& f) { return (double(fs::file_size(f)) - double(payload_bytes)) / double(samples); };
        std::printf("\nexport of %llu samples: SQLite -> MCAP %.2f s (%.0f samples/s), MCAP -> SQLite %.2f s (%.0f samples/s)\n",
                    (unsigned long long)samples, to_mcap_s, double(samples) / to_mcap_s, to_sqlite_s, double(samples) / to_sqlite_s);
        std::printf("bytes per sample beyond its payload: MCAP %.1f, SQLite %.1f (index included)\n", size_of(mcap), size_of(file));
        std::printf("loading into a store: MCAP %.2f s, SQLite %.2f s (%.2fx); %llu samples from MCAP\n", load_mcap_s, load_s, load_mcap_s / load_s,
                    (unsigned long long)from_mcap.samples);
        bench::record({"recording", "export SQLite -> MCAP", "samples/s", double(samples) / to_mcap_s, "MCAP -> SQLite", double(samples) / to_sqlite_s});
        bench::record({"recording", "MCAP bytes per sample beyond its payload", "bytes", size_of(mcap), "SQLite's", size_of(file)});
        bench::record({"recording", "loading an MCAP recording into a store", "s", load_mcap_s, "loading its SQLite recording", load_s});
    }

    // 3. Size.
    const double per_sample = (double(fs::file_size(file)) - double(payload_bytes)) / double(samples);
    std::printf("\nfile: %.1f MiB for %llu samples of 150 bytes: %.1f bytes per sample beyond its payload (index included)\n",
                double(fs::file_size(file)) / 1048576.0, (unsigned long long)samples, per_sample);

    // 4. Replay timing at rate 1: 2000 samples recorded 5 ms apart (200 Hz, 10 s).
    const std::string play_file = (dir / "play.db").string();
    {
        Store store;
        RecordingWriter writer(play_file);
        const Oid o = store.add_object({.topic = "vehicleState", .key = "1", .type_name = "VehicleState", .created_ts = 1});
        writer.object_added(*store.info(o));
        VehicleState vs;
        vs.vehicle_id(1);
        VehicleStatePubSubType type;
        eprosima::fastrtps::rtps::SerializedPayload_t wire(type.m_typeSize);
        for (uint64_t i = 0; i < 2000; ++i) {
            const uint64_t now = 1'000'000'000ull + i * 5'000'000ull;
            cpm::stamp_message(vs, now, 0);
            type.serialize(&vs, &wire);
            std::vector<uint8_t> payload(wire.data, wire.data + wire.length);
            Incoming in{now, now, now, payload.data(), payload.size(), 0};
            writer.sample_committed(o, in, store.commit(o, in, now));
        }
    }
    cpm::Participant player_participant(options_for(domain + 2, true));
    cpm::rtdb::Player player(player_participant, play_file, {.wait_for_readers_ns = 0});
    const auto stats = player.run();
    std::printf("\ncpm play at rate 1: %llu samples recorded 5 ms apart; leaving late by p50 %.3f ms, p99 %.3f ms, max %.3f ms\n",
                (unsigned long long)stats.published, stats.late_p50_ns * 1e-6, stats.late_p99_ns * 1e-6, stats.late_max_ns * 1e-6);
    fs::remove_all(dir);
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "bench_recording", kHelp, run); }
