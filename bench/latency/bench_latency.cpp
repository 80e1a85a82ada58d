// Ping-pong latency between two processes: cpm Writer/AsyncReader versus raw Fast DDS with
// the same QoS and transport, Cyclone DDS's ddsperf, and Cyclone doing this same work
// (cyclone_bench from the same IDL), in one run.
//
//   bench_latency [--count 10000] [--warmup 1000] [--sizes 100,65536] [--domain 200]
//
// One-way latency = round trip / 2, as ddsperf reports it. Reliable, keep-last 1.
#include "bench_common.hpp"
#include "raw_fastdds.hpp"

#include <cpm/AsyncReader.hpp>
#include <cpm/CommandLine.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/Writer.hpp>
#include <cpm/init.hpp>

#include <BenchPayload.h>

#include <fastdds/dds/core/condition/WaitSet.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <thread>

#include <csignal>
#include <unistd.h>

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;
namespace fdds = eprosima::fastdds::dds;

namespace {

// A ping unanswered for this long during warm-up is sent again (a reply can be lost only
// before both directions have matched); in the measured phase it is a failure.
constexpr auto kResendAfter = 500ms;
constexpr int kMaxTries = 20;

const cpm::WriterOptions kWriterOptions{.reliable = true, .keep_all = false, .history_depth = 1, .data_sharing = bench::data_sharing()};
const cpm::ReaderOptions kReaderOptions{.reliable = true, .keep_all = false, .history_depth = 1, .data_sharing = bench::data_sharing()};

/// cpm's default transports (loopback UDP + shared memory), or loopback UDP only (the
/// transport Cyclone's ddsperf uses here); `security`: a node's security folder (DDS Security).
cpm::ParticipantOptions options_for(int domain, bool shared_memory = true, const std::string& security = "")
{
    cpm::ParticipantOptions o;
    o.domain_id = domain;
    o.name = "bench_latency";
    o.shared_memory = shared_memory;
    o.security = security;
    bench::apply_link_end(o);
    return o;
}

BenchPayload payload_of_size(size_t size)
{
    BenchPayload p;
    p.data().resize(size > 28 ? size - 28 : 0);  // 16 header + 8 seq + 4 length
    return p;
}

std::atomic<bool> g_stop{false};

// ---- pong side: echoes every ping back on "pong" ----------------------------------------

/// `dds_thread`: the callback runs on the DDS receive thread (ReaderOptions::dds_thread_callback).
void pong_cpm(int domain, bool shared_memory, const std::string& security = "", bool dds_thread = false)
{
    cpm::Participant participant(options_for(domain, shared_memory, security));
    cpm::Writer<BenchPayload> pong(participant, "pong", kWriterOptions);
    cpm::ReaderOptions reader_options = kReaderOptions;
    reader_options.dds_thread_callback = dds_thread;
    cpm::AsyncReader<BenchPayload> ping(
        [&](std::vector<BenchPayload>& batch) {
            for (auto& s : batch) (void)pong.write(s);
        },
        participant, "ping", reader_options);
    while (!g_stop) std::this_thread::sleep_for(50ms);
}

struct EchoListener : fdds::DataReaderListener
{
    fdds::DataWriter* writer = nullptr;
    BenchPayload sample;
    void on_data_available(fdds::DataReader* reader) override
    {
        fdds::SampleInfo info;
        while (reader->take_next_sample(&sample, &info) == ReturnCode_t::RETCODE_OK) {
            if (info.valid_data) writer->write(&sample);
        }
    }
};

void pong_raw_listener(int domain)
{
    cpm::Participant participant(options_for(domain));
    bench::RawEndpoints raw(participant);
    EchoListener echo;
    echo.writer = raw.writer("pong", false, 1);
    raw.reader("ping", false, 1, &echo);
    while (!g_stop) std::this_thread::sleep_for(50ms);
}

void pong_raw_waitset(int domain)
{
    cpm::Participant participant(options_for(domain));
    bench::RawEndpoints raw(participant);
    fdds::DataWriter* writer = raw.writer("pong", false, 1);
    fdds::DataReader* reader = raw.reader("ping", false, 1, nullptr);
    fdds::WaitSet waitset;
    reader->get_statuscondition().set_enabled_statuses(fdds::StatusMask::data_available());
    waitset.attach_condition(reader->get_statuscondition());
    BenchPayload sample;
    fdds::SampleInfo info;
    fdds::ConditionSeq triggered;
    while (!g_stop) {
        waitset.wait(triggered, eprosima::fastrtps::Duration_t(0, 100'000'000));
        while (reader->take_next_sample(&sample, &info) == ReturnCode_t::RETCODE_OK) {
            if (info.valid_data) writer->write(&sample);
        }
    }
}

// ---- ping side: measures round trips ----------------------------------------------------

// One ping endpoint pair; run() measures a block of round trips. All cases stay connected
// for the whole run, and blocks of each case alternate, so machine noise hits all alike.
class Pinger
{
public:
    virtual ~Pinger() = default;
    virtual bool connected() = 0;
    // Appends one-way latencies (us) of `count` round trips after `warmup` unmeasured ones.
    bool run(size_t size, int count, int warmup, std::vector<double>& one_way_us)
    {
        BenchPayload sample = payload_of_size(size);
        for (int i = 0; i < warmup + count; ++i) {
            sample.seq(++seq_);
            const auto t0 = Clock::now();
            write(sample);
            bool answered = false;
            for (int tries = 0; !answered; ++tries) {
                if (!wait_reply(seq_, answered)) {
                    // At start-up the pong's writer may not have matched our reader yet.
                    if (tries == kMaxTries || i >= warmup) return false;
                    write(sample);
                }
            }
            const double us = std::chrono::duration<double, std::micro>(Clock::now() - t0).count() / 2;
            if (i >= warmup) one_way_us.push_back(us);
        }
        return true;
    }

protected:
    virtual void write(const BenchPayload& sample) = 0;
    // Waits up to kResendAfter; false on timeout, else sets `answered` if seq came back.
    virtual bool wait_reply(uint64_t seq, bool& answered) = 0;
    uint64_t seq_ = 0;
};

class CpmPinger : public Pinger
{
public:
    CpmPinger(int domain, bool shared_memory, const std::string& security = "")
        : participant_(options_for(domain, shared_memory, security)),
          ping_(participant_, "ping", kWriterOptions),
          pong_(participant_, "pong", kReaderOptions)
    {
    }
    bool connected() override { return ping_.wait_for_matched(1, 10s) && pong_.wait_for_matched(1, 10s); }

private:
    void write(const BenchPayload& sample) override { (void)ping_.write(sample); }
    bool wait_reply(uint64_t seq, bool& answered) override
    {
        if (!pong_.wait_for_data(kResendAfter)) return false;
        for (auto& s : pong_.take()) answered = answered || s.seq() == seq;
        return true;
    }
    cpm::Participant participant_;
    cpm::Writer<BenchPayload> ping_;
    cpm::ReaderAbstract<BenchPayload> pong_;
};

class RawPinger : public Pinger
{
public:
    explicit RawPinger(int domain) : participant_(options_for(domain)), raw_(participant_)
    {
        ping_ = raw_.writer("ping", false, 1);
        pong_ = raw_.reader("pong", false, 1, nullptr);
        pong_->get_statuscondition().set_enabled_statuses(fdds::StatusMask::data_available());
        waitset_.attach_condition(pong_->get_statuscondition());
    }
    bool connected() override
    {
        const auto deadline = Clock::now() + 10s;
        fdds::PublicationMatchedStatus pm;
        fdds::SubscriptionMatchedStatus sm;
        do {
            std::this_thread::sleep_for(10ms);
            ping_->get_publication_matched_status(pm);
            pong_->get_subscription_matched_status(sm);
        } while ((pm.current_count < 1 || sm.current_count < 1) && Clock::now() < deadline);
        return pm.current_count >= 1 && sm.current_count >= 1;
    }

private:
    void write(const BenchPayload& sample) override { ping_->write(const_cast<BenchPayload*>(&sample)); }
    bool wait_reply(uint64_t seq, bool& answered) override
    {
        fdds::ConditionSeq triggered;
        if (waitset_.wait(triggered, eprosima::fastrtps::Duration_t(0, 500'000'000)) != ReturnCode_t::RETCODE_OK) {
            return false;
        }
        fdds::SampleInfo info;
        while (pong_->take_next_sample(&reply_, &info) == ReturnCode_t::RETCODE_OK) {
            answered = answered || (info.valid_data && reply_.seq() == seq);
        }
        return true;
    }
    cpm::Participant participant_;
    bench::RawEndpoints raw_;
    fdds::DataWriter* ping_ = nullptr;
    fdds::DataReader* pong_ = nullptr;
    fdds::WaitSet waitset_;
    BenchPayload reply_;
};

// ---- Cyclone DDS: ddsperf ping/pong, pinned to loopback ---------------------------------

// ddsperf prints one line per second: "... size S mean Xus min Xus 50% Xus 90% Xus 99% Xus max Xus cnt N".
// Percentiles are per one-second window; we report the median window's value (first window
// dropped as warm-up), and min/max/n over all windows.
bench::Stats ddsperf_latency(int domain, size_t size, int seconds, size_t& windows)
{
    const std::string pong_out = "/tmp/bench_ddsperf_pong_" + std::to_string(getpid());
    const std::string ping_out = "/tmp/bench_ddsperf_ping_" + std::to_string(getpid());
    const std::vector<std::string> env{bench::cyclone_env_here()};
    const std::string dur = std::to_string(seconds + 2);
    auto pong = bench::spawn(bench::on_far_side({"/usr/bin/ddsperf", "-i", std::to_string(domain), "-D", dur, "pong"}), {bench::cyclone_env_far()}, pong_out);
    auto ping = bench::spawn({"/usr/bin/ddsperf", "-i", std::to_string(domain), "-D", std::to_string(seconds),
                                   "ping", "size", std::to_string(size)},
                                  env, ping_out);
    bench::wait_child(ping, seconds + 20);
    pong.signal(SIGTERM);
    bench::wait_child(pong, 5);

    std::vector<double> p50s, p90s, p99s;
    bench::Stats s;
    s.min = 1e300;
    std::ifstream in(ping_out);
    bool first = true;
    for (std::string line; std::getline(in, line);) {
        const auto pos = line.find(" mean ");
        if (pos == std::string::npos || line.find(" cnt ") == std::string::npos) continue;
        std::map<std::string, double> v;
        std::istringstream fields(line.substr(pos));
        for (std::string key, value; fields >> key >> value;) v[key] = std::atof(value.c_str());
        if (first) {
            first = false;
            continue;
        }
        s.n += static_cast<size_t>(v["cnt"]);
        s.min = std::min(s.min, v["min"]);
        s.max = std::max(s.max, v["max"]);
        p50s.push_back(v["50%"]);
        p90s.push_back(v["90%"]);
        p99s.push_back(v["99%"]);
    }
    std::remove(pong_out.c_str());
    std::remove(ping_out.c_str());
    windows = p50s.size();
    if (p50s.empty()) return {};
    s.p50 = bench::stats_of(p50s).p50;
    s.p90 = bench::stats_of(p90s).p50;
    s.p99 = bench::stats_of(p99s).p50;
    return s;
}

const char* kHelp =
    "usage: bench_latency [--count 10000] [--warmup 1000] [--sizes 100,65536] [--domain 200]\n"
    "                     [--link loopback|veth]\n"
    "One-way latency (round trip / 2) between two processes: cpm against raw Fast DDS, Cyclone DDS's\n"
    "ddsperf and Cyclone doing the same work, in one run; uses domains D to D+7.\n"
    "  --count N        round trips per case and size, in 10 alternating blocks (at least 10)\n"
    "  --warmup N       round trips discarded before the first block\n"
    "  --sizes A,B,...  payload sizes in bytes, each at most 65536\n"
    "  --link veth      the pongs on a second host: network namespaces joined by a veth pair\n"
    "                   (root), each side given its address and the other as peer (default\n"
    "                   loopback: one host)\n"
    "(--role pong --impl IMPL --security DIR --interface A --peer B: the pongs it starts)\n";

int run(int argc, char** argv)
{
    const auto flags = cpm::cli::parse_flags(
        argc, argv, {{"--count", true}, {"--warmup", true}, {"--sizes", true}, {"--domain", true}, {"--role", true}, {"--impl", true},
                     {"--link", true}, {"--interface", true}, {"--peer", true}},
        "bench_latency");
    const std::string role = flags.get("--role", "main");
    // The run uses domains D to D+7; each pong process one of them.
    const int domain = int(cpm::cli::parse_integer("--domain", flags.get("--domain", "200"), 0, role == "pong" ? 232 : 225));
    if (role == "pong") {
        std::signal(SIGTERM, [](int) { g_stop = true; });
        bench::set_link_end(flags.get("--interface"), flags.get("--peer"));
        const std::string impl = flags.get("--impl", "cpm");
        if (impl == "cpm" || impl == "cpm_udp") pong_cpm(domain, impl == "cpm");
        else if (impl == "cpm_dds_thread") pong_cpm(domain, true, "", true);
        else if (impl == "cpm_secured") pong_cpm(domain, true, cpm::parse_init_settings(argc, argv, nullptr).security);
        else if (impl == "raw_listener") pong_raw_listener(domain);
        else pong_raw_waitset(domain);
        return 0;
    }
    if (role != "main") throw cpm::cli::UsageError("bench_latency: --role '" + role + "' is neither main nor pong");
    const int count = int(cpm::cli::parse_integer("--count", flags.get("--count", "10000"), 10, 10'000'000));
    const int warmup = int(cpm::cli::parse_integer("--warmup", flags.get("--warmup", "1000"), 0, 1'000'000));
    const auto listed = bench::integer_list("--sizes", flags.get("--sizes", "100,65536"), 1, 65536);
    const std::vector<size_t> sizes(listed.begin(), listed.end());

    const std::string link = flags.get("--link", "loopback");
    if (link != "loopback" && link != "veth") throw cpm::cli::UsageError("bench_latency: --link '" + link + "' is neither loopback nor veth");
    if (link == "veth") (void)bench::use_veth_link();
    bench::print_machine("reliable, keep-last 1, volatile; " +
                         std::string(link == "veth" ? "pongs on a second host (network namespace) across a veth pair"
                                                    : "loopback UDP + shared memory (cpm defaults)") + "; " +
                         std::to_string(count) + " round trips after " + std::to_string(warmup) +
                         " warm-up; one-way = RTT/2 in microseconds; each case its own pong process and domain, "
                         "cases alternating in 10 blocks");
    int exit_code = 0;
    struct Case
    {
        std::string impl, label;
    };
    const std::vector<Case> cases{{"cpm", "cpm Writer/AsyncReader"},
                                  {"cpm_dds_thread", "cpm, callback on the DDS thread"},
                                  {"cpm_udp", "cpm, loopback UDP only"},
                                  {"raw_listener", "raw Fast DDS (listener pong)"},
                                  {"raw_waitset", "raw Fast DDS (wait-set pong)"},
                                  {"cpm_secured", "cpm, DDS Security (AES-GCM, all protected)"}};
    const bench::SecuredLab lab;
    const int rounds = 10;
    for (size_t size : sizes) {
        bench::print_header("one-way latency, payload " + std::to_string(size) + " B");
        // Every case gets its own domain and pong process for the whole run.
        std::vector<cpm::ChildProcess> pongs;
        std::vector<std::unique_ptr<Pinger>> pingers;
        for (size_t k = 0; k < cases.size(); ++k) {
            const int d = domain + int(k);
            pongs.push_back(bench::spawn(bench::far_side({cpm::sibling_executable("bench_latency"), "--role", "pong", "--impl", cases[k].impl,
                                                          "--domain", std::to_string(d), "--security", lab.node}),
                                         {}, ""));
            if (cases[k].impl == "cpm" || cases[k].impl == "cpm_udp" || cases[k].impl == "cpm_dds_thread")
                pingers.push_back(std::make_unique<CpmPinger>(d, cases[k].impl != "cpm_udp"));
            else if (cases[k].impl == "cpm_secured")
                pingers.push_back(std::make_unique<CpmPinger>(d, true, lab.node));
            else pingers.push_back(std::make_unique<RawPinger>(d));
        }
        // Cyclone doing the same work takes its turn in every block too.
        const int cyclone_domain = domain + int(cases.size()) + 1;
        const std::vector<std::string> cyclone_pong{cpm::sibling_executable("cyclone_bench"), "pong", "--domain", std::to_string(cyclone_domain)};
        pongs.push_back(bench::spawn(bench::on_far_side(cyclone_pong), {bench::cyclone_env_far()}, ""));
        std::vector<std::vector<double>> samples(cases.size());
        std::vector<double> cyclone_samples;
        bool cyclone_ok = true;
        std::vector<bool> ok(cases.size(), true);
        for (size_t k = 0; k < cases.size(); ++k) ok[k] = pingers[k]->connected();
        bench::CyclonePinger cyclone(cyclone_domain, size);  // one ping process, warm across the blocks as cpm's
        for (int round = 0; round < rounds; ++round) {
            const int block_warmup = round == 0 ? warmup : 50;
            for (size_t k = 0; k < cases.size(); ++k) {
                if (!ok[k]) continue;
                ok[k] = pingers[k]->run(size, count / rounds, block_warmup, samples[k]);
            }
            if (cyclone_ok) cyclone_ok = cyclone.block(count / rounds, block_warmup, cyclone_samples);
        }
        pingers.clear();
        for (auto& pong : pongs) pong.signal(SIGTERM);
        for (auto& pong : pongs) bench::wait_child(pong, 10);

        std::map<std::string, bench::Stats> results;
        for (size_t k = 0; k < cases.size(); ++k) {
            if (!ok[k]) {
                std::printf("%-44s FAILED after %zu round trips\n", cases[k].label.c_str(), samples[k].size());
                exit_code = 1;
                continue;
            }
            results[cases[k].impl] = bench::stats_of(samples[k]);
            bench::print_row(cases[k].label, results[cases[k].impl]);
        }
        if (cyclone_ok) {
            results["cyclone_same"] = bench::stats_of(cyclone_samples);
            bench::print_row("Cyclone, same work (wait-set pong, UDP)", results["cyclone_same"]);
        } else {
            std::printf("%-44s FAILED after %zu round trips\n", "Cyclone, same work (wait-set pong, UDP)", cyclone_samples.size());
            exit_code = 1;
        }
        const int seconds = 5;
        size_t windows = 0;
        results["cyclone"] = ddsperf_latency(domain + int(cases.size()), size, seconds, windows);
        bench::print_row("Cyclone DDS ddsperf ping/pong (" + std::to_string(seconds) + " s)", results["cyclone"]);
        // ddsperf prints a line a second; the first is warm-up. Fewer windows: an incomplete run.
        const bool cyclone_complete = windows + 2 >= size_t(seconds);
        const std::string sized = std::to_string(size) + " B one-way";
        if (results.count("cpm") && results.count("raw_listener")) {
            bench::print_ratio("cpm / raw Fast DDS (listener pong)", results["cpm"], results["raw_listener"]);
            bench::record_latency("latency", sized, results["cpm"], "raw Fast DDS (listener pong)", results["raw_listener"]);
        }
        // The like-for-like pair: both answer on the DDS receive thread.
        if (results.count("cpm_dds_thread") && results.count("raw_listener")) {
            bench::print_ratio("cpm DDS-thread callback / raw Fast DDS (listener pong)", results["cpm_dds_thread"], results["raw_listener"]);
            bench::record_latency("latency", sized + ", callback on the DDS thread", results["cpm_dds_thread"],
                                  "raw Fast DDS (listener pong)", results["raw_listener"], 1.05);
        }
        if (results.count("cpm") && results.count("cpm_secured")) {
            bench::print_ratio("cpm secured / cpm unsecured", results["cpm_secured"], results["cpm"]);
            bench::record_latency("latency", sized + ", DDS Security", results["cpm_secured"], "cpm unsecured", results["cpm"]);
        }
        if (results.count("cpm") && results.count("raw_waitset")) {
            bench::print_ratio("cpm / raw Fast DDS (wait-set pong)", results["cpm"], results["raw_waitset"]);
            bench::record_latency("latency", sized, results["cpm"], "raw Fast DDS (wait-set pong)", results["raw_waitset"]);
        }
        if (!cyclone_complete) {
            std::printf("Cyclone DDS: %zu of %d one-second windows; incomplete, no ratio\n", windows, seconds - 1);
            exit_code = 1;
        } else {
            // Not the same estimator: ddsperf's figures are medians of its per-second percentiles,
            // and ddsperf runs on loopback UDP (its shared memory needs iceoryx); cpm's are
            // per-sample percentiles.
            if (results.count("cpm")) bench::print_ratio("cpm / Cyclone (UDP; its per-second medians)", results["cpm"], results["cyclone"]);
            if (results.count("cpm_udp"))
                bench::print_ratio("cpm UDP only / Cyclone (same transport)", results["cpm_udp"], results["cyclone"]);
        }
        // The same work and estimator: per-sample percentiles, a ping process waiting on a wait set.
        if (results.count("cyclone_same")) {
            if (results.count("cpm")) bench::print_ratio("cpm (default transports) / Cyclone, same work", results["cpm"], results["cyclone_same"]);
            // The record against Cyclone: the same work on the same transport (UDP), the same estimator.
            if (results.count("cpm_udp")) {
                bench::print_ratio("cpm UDP only / Cyclone, same work (same transport)", results["cpm_udp"], results["cyclone_same"]);
                bench::record_latency("latency", sized + ", UDP", results["cpm_udp"], "Cyclone, same work (wait-set pong, UDP)", results["cyclone_same"]);
            }
            if (results.count("raw_listener"))
                bench::print_ratio("raw Fast DDS listener / Cyclone, same work", results["raw_listener"], results["cyclone_same"]);
        }
    }
    return exit_code;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "bench_latency", kHelp, run); }
