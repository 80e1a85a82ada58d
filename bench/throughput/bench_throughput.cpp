// Throughput of 1 KiB reliable samples from a publisher process to a subscriber process,
// with none lost: cpm Writer/AsyncReader versus raw Fast DDS with the same QoS and
// transport, Cyclone DDS's ddsperf pub/sub, and Cyclone doing this same work (cyclone_bench,
// sample by sample and batched), in one run.
//
//   bench_throughput [--seconds 5] [--size 1024] [--domain 201]
//
// The publisher writes as fast as the writer accepts for the given time, then an end marker;
// the subscriber counts, checks sequence numbers for gaps and reports samples per second
// between its first and last sample.
#include "bench_common.hpp"
#include "raw_fastdds.hpp"

#include <cpm/AsyncReader.hpp>
#include <cpm/CommandLine.hpp>
#include <cpm/Writer.hpp>
#include <cpm/init.hpp>

#include <BenchPayload.h>

#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <mutex>
#include <sstream>
#include <thread>

#include <unistd.h>

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;
namespace fdds = eprosima::fastdds::dds;

namespace {

constexpr uint64_t kEndMarker = UINT64_MAX;
const cpm::WriterOptions kWriterOptions{.reliable = true, .keep_all = true, .data_sharing = bench::data_sharing()};
const cpm::ReaderOptions kReaderOptions{.reliable = true, .keep_all = true, .data_sharing = bench::data_sharing()};

/// cpm's default transports (loopback UDP + shared memory) for "cpm" and "raw"; loopback UDP
/// only for "cpm_udp" (the transport Cyclone's ddsperf uses here).
/// "cpm_secured": cpm's defaults with DDS Security, as the node whose folder this names.
std::string g_security;

cpm::ParticipantOptions options_for(int domain, const std::string& impl)
{
    cpm::ParticipantOptions o;
    o.domain_id = domain;
    o.name = "bench_throughput";
    o.shared_memory = impl != "cpm_udp";
    bench::apply_link_end(o);
    if (impl == "cpm_secured") o.security = g_security;
    return o;
}

bool is_cpm(const std::string& impl) { return impl == "cpm" || impl == "cpm_udp" || impl == "cpm_secured"; }

// Counts samples and gaps; shared by the cpm and raw subscribers.
struct Counter
{
    std::mutex mutex;
    uint64_t received = 0, lost = 0, next_seq = 0;
    Clock::time_point first, last;
    std::atomic<bool> done{false};

    void add(uint64_t seq)
    {
        std::lock_guard<std::mutex> lock(mutex);
        if (seq == kEndMarker) {
            done = true;
            return;
        }
        const auto now = Clock::now();
        if (received == 0) first = now;
        last = now;
        ++received;
        if (seq > next_seq) lost += seq - next_seq;
        next_seq = seq + 1;
    }
    void report()
    {
        const double seconds = std::chrono::duration<double>(last - first).count();
        std::printf("received %llu lost %llu seconds %.6f\n", (unsigned long long)received, (unsigned long long)lost,
                    seconds);
        std::fflush(stdout);
    }
};

struct CountingListener : fdds::DataReaderListener
{
    Counter* counter;
    BenchPayload sample;
    void on_data_available(fdds::DataReader* reader) override
    {
        fdds::SampleInfo info;
        while (reader->take_next_sample(&sample, &info) == ReturnCode_t::RETCODE_OK) {
            if (info.valid_data) counter->add(sample.seq());
        }
    }
};

int subscribe(const std::string& impl, int domain, int max_seconds)
{
    Counter counter;
    cpm::Participant participant(options_for(domain, impl));
    std::unique_ptr<cpm::AsyncReader<BenchPayload>> cpm_reader;
    std::unique_ptr<bench::RawEndpoints> raw;
    CountingListener listener;
    listener.counter = &counter;
    if (is_cpm(impl)) {
        cpm_reader = std::make_unique<cpm::AsyncReader<BenchPayload>>(
            [&](std::vector<BenchPayload>& batch) {
                for (auto& s : batch) counter.add(s.seq());
            },
            participant, "throughput", kReaderOptions);
    } else {
        raw = std::make_unique<bench::RawEndpoints>(participant);
        raw->reader("throughput", true, 1, &listener);
    }
    const auto deadline = Clock::now() + std::chrono::seconds(max_seconds);
    while (!counter.done && Clock::now() < deadline) std::this_thread::sleep_for(5ms);
    counter.report();
    return counter.done ? 0 : 3;
}

// Returns the number of samples written.
uint64_t publish(const std::string& impl, int domain, size_t size, int seconds)
{
    cpm::Participant participant(options_for(domain, impl));
    BenchPayload sample;
    sample.data().resize(size > 28 ? size - 28 : 0);
    std::unique_ptr<cpm::Writer<BenchPayload>> writer;
    std::unique_ptr<bench::RawEndpoints> raw;
    fdds::DataWriter* raw_writer = nullptr;
    if (is_cpm(impl)) {
        writer = std::make_unique<cpm::Writer<BenchPayload>>(participant, "throughput", kWriterOptions);
        if (!writer->wait_for_matched(1, 10s)) std::fprintf(stderr, "bench_throughput: no reader matched within 10 s\n");
    } else {
        raw = std::make_unique<bench::RawEndpoints>(participant);
        raw_writer = raw->writer("throughput", true, 1);
        fdds::PublicationMatchedStatus status;
        const auto deadline = Clock::now() + 10s;
        do {
            std::this_thread::sleep_for(10ms);
            raw_writer->get_publication_matched_status(status);
        } while (status.current_count < 1 && Clock::now() < deadline);
    }
    auto write = [&](const BenchPayload& s) { return writer ? writer->write(s) : bool(raw_writer->write((void*)&s)); };

    uint64_t seq = 0;
    const auto end = Clock::now() + std::chrono::seconds(seconds);
    while (Clock::now() < end) {
        sample.seq(seq);
        if (write(sample)) ++seq;  // a refused write (history full) is retried, not lost
    }
    sample.seq(kEndMarker);
    while (!write(sample)) {
    }
    if (writer) writer->wait_for_acknowledgments(30s);
    else raw_writer->wait_for_acknowledgments(eprosima::fastrtps::Duration_t(30, 0));
    return seq;
}

using Result = bench::Rate;

Result run_fastdds(const std::string& impl, int domain, size_t size, int seconds)
{
    const std::string out = "/tmp/bench_throughput_sub_" + std::to_string(getpid());
    std::vector<std::string> sub_argv{cpm::sibling_executable("bench_throughput"), "--role", "sub", "--impl", impl, "--domain",
                                      std::to_string(domain), "--seconds", std::to_string(seconds + 60)};
    if (!g_security.empty()) sub_argv.insert(sub_argv.end(), {"--security", g_security});
    auto sub = bench::spawn(bench::far_side(sub_argv), {}, out);
    Result r;
    r.written = publish(impl, domain, size, seconds);
    const int code = bench::wait_child(sub, seconds + 90);
    std::ifstream in(out);
    std::string word;
    double secs = 0;
    in >> word >> r.received >> word >> r.lost >> word >> secs;
    std::remove(out.c_str());
    r.ok = code == 0 && r.received == r.written && r.lost == 0;
    r.rate = secs > 0 ? double(r.received) / secs : 0;
    return r;
}

// ddsperf sub prints per second: "... size S total T lost L delta D lost L rate R kS/s ...".
Result run_ddsperf(int domain, size_t size, int seconds)
{
    const std::string sub_out = "/tmp/bench_ddsperf_sub_" + std::to_string(getpid());
    auto sub = bench::spawn(bench::on_far_side({"/usr/bin/ddsperf", "-i", std::to_string(domain), "-D", std::to_string(seconds + 2), "sub"}),
                            {bench::cyclone_env_far()}, sub_out);
    auto pub = bench::spawn({"/usr/bin/ddsperf", "-i", std::to_string(domain), "-D", std::to_string(seconds), "pub", "size", std::to_string(size)},
                            {bench::cyclone_env_here()}, "/dev/null");
    bench::wait_child(pub, seconds + 20);
    bench::wait_child(sub, seconds + 20);
    Result r;
    std::vector<double> rates;
    std::ifstream in(sub_out);
    for (std::string line; std::getline(in, line);) {
        const auto pos = line.find(" total ");
        if (pos == std::string::npos) continue;
        std::istringstream f(line.substr(pos));
        std::string w;
        uint64_t total = 0, lost_total = 0, delta = 0, lost_delta = 0;
        double rate = 0;
        f >> w >> total >> w >> lost_total >> w >> delta >> w >> lost_delta >> w >> rate;
        r.received = total;
        r.lost = lost_total;
        if (delta > 0) rates.push_back(rate * 1000);
    }
    std::remove(sub_out.c_str());
    // Whole seconds of publishing only: drop the first and last (partial) windows.
    if (rates.size() > 2) rates = std::vector<double>(rates.begin() + 1, rates.end() - 1);
    r.rate = rates.empty() ? 0 : bench::stats_of(rates).p50;
    r.ok = r.received > 0 && r.lost == 0;
    return r;
}

// Cyclone DDS doing this same work: cyclone_bench (the same IDL through idlc; keep-all reliable;
// loopback UDP), sample by sample or with its writes batched as ddsperf always does; taken on a
// thread of its own from a wait set (as cpm's AsyncReader) or in the listener (as raw Fast DDS
// and ddsperf).
Result run_cyclone_bench(int domain, size_t size, int seconds, bool batch, bool listener)
{
    std::vector<std::string> pub_extra, sub_extra;
    if (batch) pub_extra.push_back("--batch");
    if (listener) sub_extra.push_back("--listener");
    return bench::cyclone_pub_sub(domain, size, seconds, pub_extra, sub_extra);
}

void print_result(const std::string& label, const Result& r)
{
    std::printf("%-44s %12.0f %12llu %8llu   %s\n", label.c_str(), r.rate, (unsigned long long)r.received,
                (unsigned long long)r.lost, r.ok ? "ok" : "INCOMPLETE");
    std::fflush(stdout);
}

const char* kHelp =
    "usage: bench_throughput [--seconds 5] [--size 1024] [--domain 201] [--only cpm|secured|raw|cyclone]\n"
    "                        [--link loopback|veth]\n"
    "Reliable samples per second from a publisher process to a subscriber process, none lost: cpm\n"
    "against raw Fast DDS, Cyclone DDS's ddsperf and Cyclone doing the same work, in one run.\n"
    "  --seconds S  how long each case writes\n"
    "  --size B     sample size in bytes, at most 65536\n"
    "  --only CASE  run one case\n"
    "  --link veth  publisher and subscriber on two hosts: network namespaces joined by a veth\n"
    "               pair (root), each side given its address and the other as peer, as a lab run\n"
    "               across hosts does (default loopback: one host)\n"
    "(--role sub --impl IMPL --security DIR --interface A --peer B: the subscribers it starts)\n";

int run(int argc, char** argv)
{
    const auto flags = cpm::cli::parse_flags(
        argc, argv, {{"--seconds", true}, {"--size", true}, {"--domain", true}, {"--only", true}, {"--role", true}, {"--impl", true},
                     {"--link", true}, {"--interface", true}, {"--peer", true}},
        "bench_throughput");
    const int domain = int(cpm::cli::parse_integer("--domain", flags.get("--domain", "201"), 0, 232));
    const int seconds = int(cpm::cli::parse_integer("--seconds", flags.get("--seconds", "5"), 1, 86400));
    const std::string role = flags.get("--role", "main");
    if (role == "sub") {
        g_security = cpm::parse_init_settings(argc, argv, nullptr).security;
        bench::set_link_end(flags.get("--interface"), flags.get("--peer"));
        return subscribe(flags.get("--impl", "cpm"), domain, seconds);
    }
    if (role != "main") throw cpm::cli::UsageError("bench_throughput: --role '" + role + "' is neither main nor sub");
    const size_t size = size_t(cpm::cli::parse_integer("--size", flags.get("--size", "1024"), 1, 65536));
    const std::string only = flags.get("--only");
    if (!only.empty() && only != "cpm" && only != "secured" && only != "raw" && only != "cyclone")
        throw cpm::cli::UsageError("bench_throughput: --only '" + only + "' is none of cpm, secured, raw, cyclone");
    const std::string link = flags.get("--link", "loopback");
    if (link != "loopback" && link != "veth") throw cpm::cli::UsageError("bench_throughput: --link '" + link + "' is neither loopback nor veth");
    if (link == "veth") (void)bench::use_veth_link();
    const std::string across = link == "veth" ? ", across a veth link" : "";
    bench::print_machine("reliable, keep-all, volatile; " +
                         std::string(link == "veth" ? "two hosts (network namespaces) joined by a veth pair, UDP between them"
                                                    : "loopback UDP + shared memory (cpm defaults)") + "; " +
                         std::to_string(size) + " B samples for " + std::to_string(seconds) +
                         " s; publisher and subscriber in separate processes");
    std::printf("\nthroughput, %zu B samples\n%-44s %12s %12s %8s\n", size, "case", "samples/s", "received", "lost");
    Result cpm_result, cpm_udp, cpm_secured, raw_result, cyclone, cyclone_same, cyclone_listener, cyclone_batched;
    if (only.empty() || only == "cpm") {
        cpm_result = run_fastdds("cpm", domain, size, seconds);
        print_result("cpm Writer/AsyncReader", cpm_result);
        cpm_udp = run_fastdds("cpm_udp", domain, size, seconds);
        print_result("cpm, loopback UDP only", cpm_udp);
    }
    if (only.empty() || only == "cpm" || only == "secured") {
        const bench::SecuredLab lab;
        g_security = lab.node;
        cpm_secured = run_fastdds("cpm_secured", domain, size, seconds);
        print_result("cpm, DDS Security (AES-GCM, all protected)", cpm_secured);
    }
    if (only.empty() || only == "raw") {
        raw_result = run_fastdds("raw", domain, size, seconds);
        print_result("raw Fast DDS (listener)", raw_result);
    }
    if (only.empty() || only == "cyclone") {
        cyclone = run_ddsperf(domain, size, seconds);
        print_result("Cyclone DDS ddsperf pub/sub (median second)", cyclone);
        cyclone_same = run_cyclone_bench(domain, size, seconds, false, false);
        print_result("Cyclone, same work: wait set (UDP)", cyclone_same);
        cyclone_listener = run_cyclone_bench(domain, size, seconds, false, true);
        print_result("Cyclone, same work: listener (UDP)", cyclone_listener);
        cyclone_batched = run_cyclone_bench(domain, size, seconds, true, true);
        print_result("Cyclone, batched writes, listener (UDP)", cyclone_batched);
    }
    // A ratio only from complete runs (every sample received, none lost, the whole time).
    // peer: the name the figure is recorded under (empty: printed only, cpm is not one side).
    auto ratio = [&](const char* label, const Result& a, const Result& b, const std::string& peer, double target) {
        if (a.ok && b.ok && b.rate > 0) {
            std::printf("%-44s %.2f\n", label, a.rate / b.rate);
            if (peer.empty()) return;
            bench::Figure f{"throughput",
                            std::to_string(size) + (&a == &cpm_udp ? " B reliable, cpm on UDP only" : &a == &cpm_secured ? " B reliable, DDS Security" : " B reliable") + across,
                            "samples/s", a.rate, peer, b.rate};
            if (target > 0) {
                char t[48];
                std::snprintf(t, sizeof t, ">= %.2fx peer", target);
                f.target = t;
                f.met = a.rate >= target * b.rate ? 1 : 0;
            }
            bench::record(f);
        } else if (a.rate > 0 || b.rate > 0) {
            std::printf("%-44s (an incomplete run: no ratio)\n", label);
        }
    };
    ratio("cpm / raw Fast DDS (same QoS and transport)", cpm_result, raw_result, "raw Fast DDS (same QoS and transport)", 0.9);
    ratio("cpm secured / cpm unsecured", cpm_secured, cpm_result, "cpm unsecured", 0);
    // Not the same work: ddsperf batches its writes, runs on loopback UDP and reports its
    // median second; cpm writes sample by sample and is timed from first to last sample.
    ratio("cpm / Cyclone ddsperf (batched, UDP)", cpm_result, cyclone, "Cyclone ddsperf (batched, UDP)", 0);
    ratio("cpm UDP only / Cyclone ddsperf (batched)", cpm_udp, cyclone, "Cyclone ddsperf (batched; cpm on UDP only)", 0);
    // The same work: sample by sample from first to last arrival, keep-all reliable, on UDP.
    ratio("cpm / Cyclone wait set", cpm_result, cyclone_same, "Cyclone, same work: wait set (UDP)", 0);
    // UDP is the path between hosts: there cpm is to carry at least half of what Cyclone does.
    ratio("cpm UDP only / Cyclone wait set", cpm_udp, cyclone_same, "Cyclone, same work: wait set (UDP; cpm on UDP only)", 0.5);
    ratio("raw Fast DDS listener / Cyclone listener", raw_result, cyclone_listener, "", 0);
    ratio("cpm / Cyclone batched + listener", cpm_result, cyclone_batched, "Cyclone, batched writes, listener (UDP)", 0);
    return (only == "cyclone" || only == "raw" || (cpm_result.ok && cpm_udp.ok)) && (only == "cyclone" || only == "cpm" || raw_result.ok) ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "bench_throughput", kHelp, run); }
