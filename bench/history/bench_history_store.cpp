// bench_history_store: the in-process store (cpm::rtdb) against SQLite doing the same work in
// the same run — an in-memory table with indexes on (object, commit) and (object, data, commit)
// (each query's ORDER BY served by its index: EXPLAIN QUERY PLAN is printed) and prepared
// statements, the storage rosbag2 used. 10 objects, 10,000 samples of 150 bytes each
// held per object; data times arrive slightly out of order (every 10th is 3 cycles late).
//
// `at` is measured two ways, each side doing the same work: "copied" returns the payload in a
// vector of its own (Store::at; SQLite's blob copied out), "in place" hands out the times and a
// pointer to the payload without touching its bytes (Store::view; sqlite3_column_blob).
//
// Appends: the store evicts what leaves its window on every commit; SQLite is timed doing the
// same (inserting and deleting the row that left the window), with a transaction per row and
// with batches of 1000 rows per transaction.
//
// Google Benchmark gives the mean per operation; a second pass times single calls and prints
// p50/p99 (raw, and less the cost of reading the clock) and the targets: in-place `at` p50 <= 200
// ns and >= 50x SQLite, a copied `at` <= 1.5x one random load in the held data, append >= 20x.
#include <cpm/rtdb/Store.hpp>

#include "bench_common.hpp"

#include <cpm/CommandLine.hpp>
#include <cpm/percentile.hpp>

#include <benchmark/benchmark.h>
#include <sqlite3.h>

#include <algorithm>
#include <malloc.h>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

constexpr int kObjects = 10;
constexpr int kSamples = 10'000;
constexpr size_t kPayload = 150;
constexpr uint64_t kCycle = 10'000'000;  // 100 Hz per object, in ns

uint64_t data_time(uint64_t i) { return i * kCycle - (i % 10 == 0 ? 3 * kCycle : 0); }

/// The store, filled: object k's sample i has commit time i * kCycle + k and data time
/// data_time(i). The window holds exactly kSamples per object.
struct StoreWork
{
    cpm::rtdb::Store store{cpm::rtdb::StoreOptions{{uint64_t(kSamples - 1) * kCycle, 1ull << 32}, 1ull << 34}};
    std::vector<cpm::rtdb::Oid> oids;
    std::vector<uint8_t> payload = std::vector<uint8_t>(kPayload, 0x5a);
    uint64_t next = 1;

    StoreWork()
    {
        for (int k = 0; k < kObjects; ++k) oids.push_back(store.add_object({.topic = "vehicleState", .key = std::to_string(k)}));
        for (; next <= kSamples; ++next) {
            for (int k = 0; k < kObjects; ++k) put(k, next);
        }
    }
    /// Object k's sample i: commit time i * kCycle + k, data time data_time(i).
    void put(int k, uint64_t i) { store.commit(oids[k], {data_time(i), data_time(i), 0, payload.data(), payload.size()}, i * kCycle + k); }
};

void check(int rc, sqlite3* db, const char* what)
{
    if (rc != SQLITE_OK && rc != SQLITE_DONE && rc != SQLITE_ROW) throw std::runtime_error(std::string(what) + ": " + sqlite3_errmsg(db));
}

struct SqliteWork
{
    sqlite3* db = nullptr;
    sqlite3_stmt *insert = nullptr, *evict = nullptr, *at_commit = nullptr, *at_data = nullptr, *range = nullptr;
    std::vector<uint8_t> payload = std::vector<uint8_t>(kPayload, 0x5a);
    uint64_t next = 1;

    SqliteWork()
    {
        check(sqlite3_open(":memory:", &db), db, "open");
        check(sqlite3_exec(db,
                           "CREATE TABLE samples(object INTEGER, commit_ns INTEGER, data_ns INTEGER, valid_after_ns INTEGER,"
                           " source_ns INTEGER, payload BLOB);"
                           "CREATE INDEX by_commit ON samples(object, commit_ns);"
                           "CREATE INDEX by_data ON samples(object, data_ns, commit_ns);",
                           nullptr, nullptr, nullptr),
              db, "schema");
        prepare("INSERT INTO samples VALUES(?1, ?2, ?3, ?3, 0, ?4)", &insert);
        prepare("DELETE FROM samples WHERE object = ?1 AND commit_ns < ?2", &evict);
        prepare("SELECT commit_ns, data_ns, valid_after_ns, source_ns, payload FROM samples WHERE object = ?1 AND commit_ns <= ?2"
                " ORDER BY commit_ns DESC LIMIT 1", &at_commit);
        prepare("SELECT commit_ns, data_ns, valid_after_ns, source_ns, payload FROM samples WHERE object = ?1 AND data_ns <= ?2"
                " ORDER BY data_ns DESC, commit_ns DESC LIMIT 1", &at_data);
        prepare("SELECT commit_ns, data_ns, valid_after_ns, source_ns, payload FROM samples WHERE object = ?1 AND commit_ns >= ?2"
                " AND commit_ns < ?3 ORDER BY commit_ns LIMIT 10000", &range);
        check(sqlite3_exec(db, "BEGIN", nullptr, nullptr, nullptr), db, "begin");
        for (; next <= kSamples; ++next) {
            for (int k = 0; k < kObjects; ++k) put(k, next);
        }
        check(sqlite3_exec(db, "COMMIT", nullptr, nullptr, nullptr), db, "commit");
    }
    ~SqliteWork()
    {
        for (auto* s : {insert, evict, at_commit, at_data, range}) sqlite3_finalize(s);
        sqlite3_close(db);
    }
    void prepare(const char* sql, sqlite3_stmt** s) { check(sqlite3_prepare_v2(db, sql, -1, s, nullptr), db, sql); }
    /// The row of StoreWork::put(k, i).
    void put(int k, uint64_t i)
    {
        sqlite3_bind_int64(insert, 1, k);
        sqlite3_bind_int64(insert, 2, int64_t(i * kCycle + k));
        sqlite3_bind_int64(insert, 3, int64_t(data_time(i)));
        sqlite3_bind_blob(insert, 4, payload.data(), int(payload.size()), SQLITE_STATIC);
        check(sqlite3_step(insert), db, "insert");
        sqlite3_reset(insert);
    }
    /// put(k, i), and what left object k's window with it deleted, as the store evicts.
    void put_and_evict(int k, uint64_t i)
    {
        put(k, i);
        if (i <= kSamples) return;
        sqlite3_bind_int64(evict, 1, k);
        sqlite3_bind_int64(evict, 2, int64_t((i - kSamples + 1) * kCycle + k));
        check(sqlite3_step(evict), db, "evict");
        sqlite3_reset(evict);
    }
    /// Appends in transactions of `batch` rows (1: each row its own, SQLite's autocommit).
    int batch = 1, in_batch = 0;
    void append(int k)
    {
        if (batch > 1 && in_batch == 0) check(sqlite3_exec(db, "BEGIN", nullptr, nullptr, nullptr), db, "begin");
        put_and_evict(k, next++);
        if (batch > 1 && ++in_batch == batch) {
            check(sqlite3_exec(db, "COMMIT", nullptr, nullptr, nullptr), db, "commit");
            in_batch = 0;
        }
    }
    /// The query plan, one line per step.
    std::string plan(sqlite3_stmt* s)
    {
        sqlite3_stmt* explain = nullptr;
        prepare(("EXPLAIN QUERY PLAN " + std::string(sqlite3_sql(s))).c_str(), &explain);
        std::string out;
        while (sqlite3_step(explain) == SQLITE_ROW) out += std::string(out.empty() ? "" : "; ") + (const char*)sqlite3_column_text(explain, 3);
        sqlite3_finalize(explain);
        return out;
    }
    /// The newest row of the statement's answer seen in place, the way Store::view answers: its
    /// times and SQLite's pointer to the payload (valid until the next step), no copy.
    size_t view(sqlite3_stmt* s, int object, uint64_t t)
    {
        sqlite3_bind_int64(s, 1, object);
        sqlite3_bind_int64(s, 2, int64_t(t));
        size_t size = 0;
        if (sqlite3_step(s) == SQLITE_ROW) {
            cpm::rtdb::SampleView v{uint64_t(sqlite3_column_int64(s, 0)), uint64_t(sqlite3_column_int64(s, 1)),
                                    uint64_t(sqlite3_column_int64(s, 2)), uint64_t(sqlite3_column_int64(s, 3)),
                                    static_cast<const uint8_t*>(sqlite3_column_blob(s, 4)), size_t(sqlite3_column_bytes(s, 4))};
            benchmark::DoNotOptimize(v);
            size = v.size;
        }
        sqlite3_reset(s);
        return size;
    }
    /// Reads rows the way the store answers: times and a copy of the payload.
    size_t query(sqlite3_stmt* s, int object, uint64_t t0, uint64_t t1 = 0)
    {
        sqlite3_bind_int64(s, 1, object);
        sqlite3_bind_int64(s, 2, int64_t(t0));
        if (t1) sqlite3_bind_int64(s, 3, int64_t(t1));
        std::vector<cpm::rtdb::StoredSample> out;
        while (sqlite3_step(s) == SQLITE_ROW) {
            cpm::rtdb::StoredSample x{uint64_t(sqlite3_column_int64(s, 0)), uint64_t(sqlite3_column_int64(s, 1)),
                                      uint64_t(sqlite3_column_int64(s, 2)), uint64_t(sqlite3_column_int64(s, 3)), {}};
            auto* b = static_cast<const uint8_t*>(sqlite3_column_blob(s, 4));
            x.payload.assign(b, b + sqlite3_column_bytes(s, 4));
            out.push_back(std::move(x));
        }
        sqlite3_reset(s);
        return out.size();
    }
};

/// The query fixtures (slot 0) and, so that they keep their window, the append targets (slot 1).
template <typename Work, int Slot>
Work& work()
{
    static Work w;
    return w;
}
auto& store_work() { return work<StoreWork, 0>(); }
auto& sqlite_work() { return work<SqliteWork, 0>(); }
auto& append_store() { return work<StoreWork, 1>(); }
auto& append_sqlite() { return work<SqliteWork, 1>(); }
auto& append_sqlite_batched()
{
    auto& w = work<SqliteWork, 2>();
    w.batch = 1000;
    return w;
}

/// Query times spread over the held window (between the 100th oldest and the 100th newest of
/// the kSamples held), drawn before any timing starts.
struct Times
{
    std::vector<uint64_t> table = std::vector<uint64_t>(1 << 16);
    size_t i = 0;
    int k = 0;  ///< the object asked last
    Times()
    {
        std::mt19937_64 rng{42};
        for (auto& t : table) t = kSamples * kCycle - kCycle * (100 + rng() % (kSamples - 200));
    }
    uint64_t t() { return table[i++ & (table.size() - 1)]; }
    /// op(object, time, by) about the next object, object after object, at the next time.
    template <typename Op>
    size_t ask(Op op, cpm::rtdb::By by)
    {
        k = (k + 1) % kObjects;
        return op(k, t(), by);
    }
};

void BM_Store_Append(benchmark::State& state)
{
    auto& w = append_store();
    for (auto _ : state) w.put(0, w.next++);
}
void BM_Sqlite_Append(benchmark::State& state)
{
    auto& w = append_sqlite();
    for (auto _ : state) w.append(0);
}
void BM_Sqlite_AppendBatched(benchmark::State& state)
{
    auto& w = append_sqlite_batched();
    for (auto _ : state) w.append(0);
}
// The four ways of asking `at`, object k at time t; each side does the same work.
using cpm::rtdb::By;
/// Store::at: the sample with its payload copied out.
size_t store_copied(int k, uint64_t t, By by) { return store_work().store.at(store_work().oids[k], t, by).sample.payload.size(); }
/// SQLite: the row with its blob copied out.
size_t sqlite_copied(int k, uint64_t t, By by)
{
    auto& q = sqlite_work();
    return q.query(by == By::data ? q.at_data : q.at_commit, k, t);
}
/// Store::view: the sample's times and where its payload lies, nothing copied.
size_t store_in_place(int k, uint64_t t, By by)
{
    auto& w = store_work();
    size_t size = 0;
    w.store.view(w.oids[k], cpm::rtdb::Which::at, t, by, [&](const cpm::rtdb::SampleView& v) {
        benchmark::DoNotOptimize(v);
        size = v.size;
    });
    return size;
}
/// SQLite: the row's times and sqlite3_column_blob's pointer, nothing copied.
size_t sqlite_in_place(int k, uint64_t t, By by)
{
    auto& q = sqlite_work();
    return q.view(by == By::data ? q.at_data : q.at_commit, k, t);
}

using AtOp = size_t (*)(int, uint64_t, By);

/// The four ways of asking `at`, each with its SQLite counterpart.
struct AtCase
{
    const char* what;
    AtOp store, sqlite;
    By by;
};
const AtCase kAtCases[] = {{"at commit, copied", store_copied, sqlite_copied, By::commit},
                           {"at data, copied", store_copied, sqlite_copied, By::data},
                           {"at commit, in place", store_in_place, sqlite_in_place, By::commit},
                           {"at data, in place", store_in_place, sqlite_in_place, By::data}};

/// Asks `op` once per iteration, object after object, at times drawn before timing.
template <AtOp op, By by>
void BM_At(benchmark::State& state)
{
    Times times;
    for (auto _ : state) benchmark::DoNotOptimize(times.ask(op, by));
}
void BM_Store_Range100(benchmark::State& state)
{
    auto& w = store_work();
    Times times;
    for (auto _ : state) {
        const uint64_t t0 = times.t();
        auto r = w.store.range(w.oids[1], t0, t0 + 100 * kCycle);
        if (r.samples.size() != 100) state.SkipWithError("range did not return 100 samples");
    }
}
void BM_Sqlite_Range100(benchmark::State& state)
{
    auto& w = sqlite_work();
    Times times;
    for (auto _ : state) {
        const uint64_t t0 = times.t();
        if (w.query(w.range, 1, t0, t0 + 100 * kCycle) != 100) state.SkipWithError("range did not return 100 rows");
    }
}

BENCHMARK(BM_Store_Append);
BENCHMARK(BM_Sqlite_Append);
BENCHMARK(BM_Sqlite_AppendBatched);
BENCHMARK(BM_At<store_copied, By::commit>)->Name("BM_Store_AtCommit");
BENCHMARK(BM_At<sqlite_copied, By::commit>)->Name("BM_Sqlite_AtCommit");
BENCHMARK(BM_At<store_copied, By::data>)->Name("BM_Store_AtData");
BENCHMARK(BM_At<sqlite_copied, By::data>)->Name("BM_Sqlite_AtData");
BENCHMARK(BM_At<store_in_place, By::commit>)->Name("BM_Store_AtCommitInPlace");
BENCHMARK(BM_At<sqlite_in_place, By::commit>)->Name("BM_Sqlite_AtCommitInPlace");
BENCHMARK(BM_At<store_in_place, By::data>)->Name("BM_Store_AtDataInPlace");
BENCHMARK(BM_At<sqlite_in_place, By::data>)->Name("BM_Sqlite_AtDataInPlace");
BENCHMARK(BM_Store_Range100);
BENCHMARK(BM_Sqlite_Range100);

/// p50 and p99 of single calls, in ns.
struct Percentiles
{
    double p50 = 0, p99 = 0;
};

/// Single calls timed one by one: p50 and p99 in ns as measured (reading the clock twice
/// included). As many calls untimed first, so that the caches hold what this operation uses
/// (not what the one before used), as Google Benchmark's own warm-up does.
template <typename F>
Percentiles percentiles(F&& op, int n = 200'000)
{
    for (int i = 0; i < n; ++i) op();
    std::vector<double> ns(n);
    for (int i = 0; i < n; ++i) {
        const auto t0 = std::chrono::steady_clock::now();
        op();
        ns[i] = double(std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - t0).count());
    }
    const bench::Stats st = bench::stats_of(std::move(ns));  // its unit is whatever is given: ns here
    return {st.p50, st.p99};
}

/// This machine's latency of one dependent load at random within `bytes` (a pointer chase):
/// what a query pays for each cache line it must fetch from that far.
double load_latency_ns(size_t bytes)
{
    const size_t n = bytes / 64;
    std::vector<size_t> order(n);
    for (size_t i = 0; i < n; ++i) order[i] = i;
    std::shuffle(order.begin(), order.end(), std::mt19937_64{7});
    std::vector<size_t> next(n * 8);  // one link per 64-byte line
    for (size_t i = 0; i < n; ++i) next[order[i] * 8] = order[(i + 1) % n] * 8;
    size_t p = 0;
    const int loads = 2'000'000;
    const auto t0 = std::chrono::steady_clock::now();
    for (int i = 0; i < loads; ++i) p = next[p];
    benchmark::DoNotOptimize(p);
    return std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count() / loads;
}

/// Mean ns per call of a block of n calls, after as many untimed.
template <typename F>
double block_ns(F&& op, int n)
{
    for (int i = 0; i < n; ++i) op();
    const auto t0 = std::chrono::steady_clock::now();
    for (int i = 0; i < n; ++i) op();
    return std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count() / n;
}

/// A single run's ratio swings with what the machine's neighbours leave in the shared cache
/// (25-83x for the same build), so each `at` case is also run in rounds that alternate store
/// and SQLite blocks; within one run the rounds agree closely, and their median is the run's ratio.
void print_rounds()
{
    constexpr int kRounds = 7, kCalls = 20'000;
    Times times;
    std::printf("interleaved rounds (%d; each a block of %d store calls, then %d SQLite calls, each warmed up first), mean ns a call:\n",
                kRounds, kCalls, kCalls);
    for (const AtCase& c : kAtCases) {
        std::vector<double> store, sqlite, ratio;
        for (int r = 0; r < kRounds; ++r) {
            store.push_back(block_ns([&] { times.ask(c.store, c.by); }, kCalls));
            sqlite.push_back(block_ns([&] { times.ask(c.sqlite, c.by); }, kCalls));
            ratio.push_back(sqlite.back() / store.back());
        }
        auto [slo, shi] = std::minmax_element(store.begin(), store.end());
        auto [qlo, qhi] = std::minmax_element(sqlite.begin(), sqlite.end());
        auto [rlo, rhi] = std::minmax_element(ratio.begin(), ratio.end());
        // One estimator, printed, recorded and judged alike: the median store block against the
        // median SQLite block (the per-round ratios show how steady the rounds were).
        const double store_median = cpm::percentile(store, 0.5), sqlite_median = cpm::percentile(sqlite, 0.5);
        const double median = sqlite_median / store_median;
        // The >= 50x target is the in-place `at`'s; a copy is judged against memory (print_percentiles).
        const bool judged = c.store == store_in_place;
        std::printf("%-20s store %6.0f-%-6.0f ns | sqlite %6.0f-%-6.0f ns | sqlite/store per round %5.1f-%-5.1fx; medians' ratio %5.1fx%s\n",
                    c.what, *slo, *shi, *qlo, *qhi, *rlo, *rhi, median,
                    !judged ? "" : median >= 50 ? " (target >= 50x: met)" : " (target >= 50x: not met)");
        bench::record({"history_store", std::string(c.what) + ", median of rounds", "ns", store_median, "SQLite (in-memory, indexed)", sqlite_median,
                       judged ? "<= 0.02x peer (50x faster)" : "", judged ? int(median >= 50) : -1});
    }
}

/// Heap the process holds: malloc's in-use bytes plus its mmap'd blocks (large allocations,
/// such as the store's chunks, live there and not in uordblks).
size_t heap_in_use()
{
    const auto m = mallinfo2();
    return m.uordblks + m.hblkhd;
}

void print_percentiles()
{
    auto& s = store_work();
    auto& q = sqlite_work();
    auto& sa = append_store();
    auto& qa = append_sqlite();
    auto& qb = append_sqlite_batched();
    Times times;
    const double clock = percentiles([] {}).p50;
    std::printf("SQLite's plans: at by commit: %s | at by data: %s | range: %s\n", q.plan(q.at_commit).c_str(), q.plan(q.at_data).c_str(),
                q.plan(q.range).c_str());
    // The store's memory per sample beyond its payload: heap in use around building a second
    // store like the query fixture (100,000 samples of 150 bytes).
    const size_t before = heap_in_use();
    auto extra = std::make_unique<StoreWork>();
    const size_t held = heap_in_use() - before;
    const auto st2 = extra->store.stats();
    extra.reset();
    const double dram_ns = load_latency_ns(held);
    std::printf("single calls; raw p50 (clock read included, %.0f ns) and less it; targets judged on raw p50:\n", clock);
    // `verdict`: the store's raw p50 against the in-place target (200 ns) or, for a copy,
    // against one random load in the held data (1.5x).
    enum Verdict { none, in_place, copied, append };
    auto line = [&](const char* what, auto&& store_op, auto&& sqlite_op, int n = 200'000, Verdict verdict = none) {
        const auto store = percentiles(store_op, n), sqlite = percentiles(sqlite_op, n);
        std::string judged;
        if (verdict == in_place) judged = store.p50 <= 200 ? " (p50 <= 200 ns: met)" : " (p50 <= 200 ns: not met)";
        if (verdict == copied) {
            char b[96];
            std::snprintf(b, sizeof b, " (p50 <= 1.5 x %.0f ns DRAM load: %s)", dram_ns, store.p50 <= 1.5 * dram_ns ? "met" : "not met");
            judged = b;
        }
        if (verdict == append) judged = sqlite.p50 >= 20 * store.p50 ? " (>= 20x: met)" : " (>= 20x: not met)";
        if (verdict == append)
            bench::record({"history_store", std::string(what) + " p50", "ns", store.p50, "SQLite (in-memory, indexed), same work", sqlite.p50,
                           "<= 0.05x peer (20x faster)", int(sqlite.p50 >= 20 * store.p50)});
        if (verdict == in_place) bench::record({"history_store", std::string(what) + " p50", "ns", store.p50, "", 0, "<= 200 ns", int(store.p50 <= 200)});
        if (verdict == copied)
            bench::record({"history_store", std::string(what) + " p50", "ns", store.p50, "one random DRAM load in the held data", dram_ns,
                           "<= 1.50x peer", int(store.p50 <= 1.5 * dram_ns)});
        std::printf("%-26s store p50 %6.0f (%6.0f) ns p99 %7.0f | sqlite p50 %7.0f (%7.0f) ns p99 %8.0f | sqlite/store p50 %6.1fx%s\n",
                    what, store.p50, store.p50 - clock, store.p99, sqlite.p50, sqlite.p50 - clock, sqlite.p99, sqlite.p50 / store.p50,
                    judged.c_str());
    };
    line("append (sqlite: txn a row)", [&] { sa.put(2, sa.next++); }, [&] { qa.append(2); }, 200'000, append);
    line("append (sqlite: 1000/txn)", [&] { sa.put(3, sa.next++); }, [&] { qb.append(3); }, 200'000, append);
    for (const AtCase& c : kAtCases) {
        line(c.what, [&] { times.ask(c.store, c.by); }, [&] { times.ask(c.sqlite, c.by); }, 200'000,
             c.store == store_in_place ? in_place : copied);
    }
    line("range 100", [&] { const uint64_t t0 = times.t(); s.store.range(s.oids[1], t0, t0 + 100 * kCycle); },
         [&] { const uint64_t t0 = times.t(); q.query(q.range, 1, t0, t0 + 100 * kCycle); }, 20'000);
    std::printf("store memory: %.1f bytes per sample beyond its payload (heap in use incl. mmap'd blocks, %llu samples; target <= 64)\n",
                (double(held) - double(st2.bytes)) / double(st2.samples), (unsigned long long)st2.samples);
    const double per_sample = (double(held) - double(st2.bytes)) / double(st2.samples);
    bench::record({"history_store", "memory per sample beyond its payload", "bytes", per_sample, "", 0, "<= 64 bytes", int(per_sample <= 64)});
    std::printf("one dependent cache-line load at random within 1 MiB: %.0f ns, 4 MiB: %.0f ns, the store's %.1f MB: %.0f ns\n"
                "(a copied `at` fetches at least one payload line from anywhere in the store, so the last figure\n"
                " bounds it from below; the in-place one does not touch the payload)\n",
                load_latency_ns(1 << 20), load_latency_ns(4 << 20), double(held) / 1e6, dram_ns);
    auto st = s.store.stats();
    std::printf("store holds %llu samples, %llu payload bytes\n", (unsigned long long)st.samples, (unsigned long long)st.bytes);
}

}  // namespace

int main(int argc, char** argv)
{
    benchmark::Initialize(&argc, argv);
    // Google Benchmark's flags (--benchmark_filter=…, --help); anything else is a usage error.
    if (benchmark::ReportUnrecognizedArguments(argc, argv)) return cpm::cli::kUsageExit;
    std::printf("bench_history_store: %d objects x %d samples of %zu bytes held; store vs SQLite (in-memory, indexed, prepared)\n",
                kObjects, kSamples, kPayload);
    // The fixtures are built before any timing: built lazily, the first benchmark to touch one
    // counted its 100,000 inserts as a query (a short or filtered run reported ~250 ms per `at`).
    store_work();
    sqlite_work();
    append_store();
    append_sqlite();
    append_sqlite_batched();
    benchmark::RunSpecifiedBenchmarks();
    print_percentiles();
    print_rounds();
    return 0;
}
