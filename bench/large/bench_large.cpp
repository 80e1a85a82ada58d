// Large samples between two processes: a 640 × 480 mono camera frame (307,200 B) and 1 MiB.
// One-way latency (ping-pong, reliable keep-last 1) and throughput (reliable keep-all, a window of
// 16 samples) for three ways cpm can carry them, beside Cyclone DDS doing the same work:
//
//   udp       BenchBlob over UDP only (shared memory off): the like of Cyclone's path here
//   shm       BenchBlob (a bounded sequence) over cpm's default shared-memory transport
//   sharing   BenchBlob with data_sharing: serialized into a pool both processes map
//   in_place  BenchFrame (plain) with data_sharing, Writer::write_in_place and
//             ReaderAbstract::take_each: written and read where it lies, no copy
//   Cyclone   cyclone_bench --type blob (BenchBlob through idlc), loopback UDP
//   Cyclone shared memory
//             cyclone_bench --type frame --loan (the plain BenchFrame, each sample loaned from
//             Cyclone: a chunk of iceoryx's shared memory), with iox-roudi (iceoryx's broker,
//             Debian's iceoryx) started for the run and SharedMemory enabled in Cyclone's file
//
// Every side that takes a sample reads each of its bytes (a checksum), in every case, Cyclone's
// too (cyclone_bench --touch): a reader uses what it receives. Each cpm path is judged against
// Cyclone's path of its class: udp against Cyclone on UDP, the shared-memory paths (shm,
// sharing, in_place) against Cyclone's shared memory, one way. Throughput has no verdict:
// Cyclone 0.10's shared-memory path takes keep-last writers only (keep-all turns it off) and
// does not hold a writer back for a slow reader, so it has no lossless keep-all run to compare.
//
//   bench_large [--count 500] [--seconds 3] [--sizes 307200,1048576] [--domain 220]
//   (domains D to D+5: one per cpm case, then Cyclone DDS on UDP and on shared memory, whose
//   highest is 232)
//
// Every sample carries only a fresh sequence number; its bytes are written once, before the run,
// in every case (as ddsperf and cyclone_bench do), so the figures are what carrying costs.
#include "bench_common.hpp"

#include <cpm/CommandLine.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/TopicType.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/read_text_file.hpp>
#include <cpm/topics.hpp>

#include <BenchLargePubSubTypes.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <numeric>
#include <memory>
#include <thread>

#include <optional>
#include <regex>
#include <sstream>

#include <poll.h>
#include <unistd.h>

CPM_REGISTER_TYPE(BenchBlob)
CPM_REGISTER_TYPE(BenchFrame307k)
CPM_REGISTER_TYPE(BenchFrame1M)

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

namespace {

constexpr uint64_t kEndMarker = UINT64_MAX;
constexpr int kWindow = 16;  // keep-all throughput: samples unacknowledged at most
std::atomic<bool> g_stop{false};

/// One process's writer on one topic and reader on another, in one of the modes.
class Side
{
public:
    virtual ~Side() = default;
    virtual bool write(uint64_t seq) = 0;
    /// Passes the sequence number of every sample that arrived; returns how many.
    virtual size_t take(const std::function<void(uint64_t)>& each) = 0;
    virtual bool wait(std::chrono::milliseconds timeout) = 0;
    virtual bool connected() = 0;         ///< both directions matched
    virtual void wait_acknowledged() = 0;
};

template <class T, bool kInPlace>
class SideOf : public Side
{
public:
    SideOf(cpm::Participant& p, const std::string& out, const std::string& in, size_t size, bool sharing, bool keep_all)
        : writer_(p, out, cpm::WriterOptions{.reliable = true, .keep_all = keep_all, .max_unacknowledged = kWindow,
                                             .data_sharing = sharing}),
          reader_(p, in, cpm::ReaderOptions{.reliable = true, .keep_all = keep_all, .data_sharing = sharing})
    {
        if constexpr (kInPlace) {
            (void)size;  // the type's own
            if (!writer_.shares_in_place()) throw std::runtime_error("in_place: the writer does not share in place");
        } else {
            sample_.data(std::vector<uint8_t>(size - 28, 0x5a));  // 16 header + 8 seq + 4 length
        }
    }
    bool write(uint64_t seq) override
    {
        if constexpr (kInPlace) {
            // A 32-bit sequence number (the type has no 8-byte field); the end marker is its maximum.
            return writer_.write_in_place([&](T& s) { s.seq(seq == kEndMarker ? UINT32_MAX : static_cast<uint32_t>(seq)); });
        } else {
            sample_.seq(seq);
            return writer_.write(sample_);
        }
    }
    size_t take(const std::function<void(uint64_t)>& each) override
    {
        return reader_.take_each([&](const T& s) {
            checksum_ = checksum_ + std::accumulate(s.data().begin(), s.data().end(), uint64_t(0));  // every byte read, where it lies
            if constexpr (kInPlace) {
                each(s.seq() == UINT32_MAX ? kEndMarker : s.seq());
            } else {
                each(s.seq());
            }
        });
    }
    bool wait(std::chrono::milliseconds timeout) override { return reader_.wait_for_data(timeout); }
    bool connected() override { return writer_.wait_for_matched(1, 20s) && reader_.wait_for_matched(1, 20s); }
    void wait_acknowledged() override { (void)writer_.wait_for_acknowledgments(30s); }

private:
    cpm::Writer<T> writer_;
    cpm::ReaderAbstract<T> reader_;
    T sample_;
    volatile uint64_t checksum_ = 0;
};

cpm::ParticipantOptions options_for(int domain, const std::string& mode = "")
{
    cpm::ParticipantOptions o;
    o.domain_id = domain;
    o.name = "bench_large";
    o.shared_memory = mode != "udp";
    bench::apply_link_end(o);
    return o;
}

std::unique_ptr<Side> make_side(cpm::Participant& p, const std::string& mode, size_t size, const std::string& out,
                                const std::string& in, bool keep_all)
{
    if (mode == "udp" || mode == "shm" || mode == "sharing")
        return std::make_unique<SideOf<BenchBlob, false>>(p, out, in, size, mode == "sharing", keep_all);
    if (mode == "in_place" && size == 307200) return std::make_unique<SideOf<BenchFrame307k, true>>(p, out, in, size, true, keep_all);
    if (mode == "in_place" && size == 1048576) return std::make_unique<SideOf<BenchFrame1M, true>>(p, out, in, size, true, keep_all);
    throw std::runtime_error("no side for mode " + mode + " and size " + std::to_string(size) +
                             " (in_place: 307200 or 1048576)");
}

// ---- child roles --------------------------------------------------------------------------

int pong(int domain, const std::string& mode, size_t size)
{
    cpm::Participant participant(options_for(domain, mode));
    auto side = make_side(participant, mode, size, "large_pong", "large_ping", false);
    while (!g_stop) {
        if (!side->wait(100ms)) continue;
        side->take([&](uint64_t seq) { (void)side->write(seq); });
    }
    return 0;
}

// Prints "received N lost L seconds S" once the end marker arrived (or max_seconds passed).
int subscribe(int domain, const std::string& mode, size_t size, int max_seconds)
{
    cpm::Participant participant(options_for(domain, mode));
    auto side = make_side(participant, mode, size, "large_ready", "large_stream", true);
    // Matched both ways, then says so: with data sharing, what a writer writes while the reader
    // is still matching it can be missed, as DDS allows for a volatile reader not yet matched.
    if (!side->connected() || !side->write(0)) return 1;
    uint64_t received = 0, lost = 0, next = 0;
    Clock::time_point first, last;
    bool done = false;
    const auto deadline = Clock::now() + std::chrono::seconds(max_seconds);
    while (!done && Clock::now() < deadline) {
        if (!side->wait(100ms)) continue;
        side->take([&](uint64_t seq) {
            if (seq == kEndMarker) {
                done = true;
                return;
            }
            last = Clock::now();
            if (received++ == 0) first = last;
            if (seq > next) lost += seq - next;
            next = seq + 1;
        });
    }
    std::printf("received %llu lost %llu seconds %.6f\n", (unsigned long long)received, (unsigned long long)lost,
                std::chrono::duration<double>(last - first).count());
    return done ? 0 : 1;
}

// A camera's stream (--camera): 307,200 B frames with cameraFrame's QoS, each stamped when
// written; the receiver prints "received N lost L" and then each frame's latency in µs (one
// machine, one clock: the stamp and the arrival are comparable across its namespaces).
int camera_receive(int domain, int max_seconds)
{
    cpm::Participant participant(options_for(domain));
    cpm::ReaderAbstract<BenchBlob> reader(participant, "large_camera", cpm::topics::camera_frame.reader);
    std::vector<double> latency_us;
    uint64_t received = 0, lost = 0, next = 0;
    bool done = false;
    const auto deadline = Clock::now() + std::chrono::seconds(max_seconds);
    while (!done && Clock::now() < deadline) {
        if (!reader.wait_for_data(100ms)) continue;
        reader.take_each([&](const BenchBlob& frame) {
            const uint64_t now = cpm::get_time_ns();
            if (frame.seq() == kEndMarker) {
                done = true;
                return;
            }
            latency_us.push_back(double(now - frame.header().create_stamp().nanoseconds()) / 1e3);
            ++received;
            if (frame.seq() > next) lost += frame.seq() - next;
            next = frame.seq() + 1;
        });
    }
    std::printf("received %llu lost %llu\n", (unsigned long long)received, (unsigned long long)lost);
    for (double v : latency_us) std::printf("%.1f\n", v);
    return done ? 0 : 1;
}

struct CameraStream
{
    bench::Stats latency;
    uint64_t written = 0, received = 0, lost = 0;
    bool ok = false;
};

/// `hz` frames a second for `seconds` to a receiver on this host or (far) across the link.
CameraStream camera_stream(int domain, int hz, int seconds, bool far)
{
    const std::string out = "/tmp/bench_large_camera_" + std::to_string(getpid());
    const std::vector<std::string> argv{cpm::sibling_executable("bench_large"), "--role", "camera", "--domain", std::to_string(domain),
                                        "--seconds", std::to_string(seconds + 30)};
    auto receiver = bench::spawn(far ? bench::far_side(argv) : argv, {}, out);
    CameraStream r;
    {
        cpm::Participant participant(options_for(domain));
        cpm::Writer<BenchBlob> writer(participant, "large_camera", cpm::topics::camera_frame.writer);
        if (!writer.wait_for_matched(1, 20s)) return r;
        std::this_thread::sleep_for(500ms);  // matched both ways
        BenchBlob frame;
        frame.data().resize(307200 - 28);
        const auto period = std::chrono::nanoseconds(1'000'000'000 / hz);
        auto next = Clock::now();
        for (int i = 0; i < hz * seconds; ++i) {
            std::this_thread::sleep_until(next);
            next += period;
            frame.seq(r.written);
            frame.header().create_stamp().nanoseconds(cpm::get_time_ns());
            if (writer.write(frame)) ++r.written;
        }
        frame.seq(kEndMarker);
        for (int i = 0; i < 10; ++i) {  // best effort: said more than once
            (void)writer.write(frame);
            std::this_thread::sleep_for(20ms);
        }
    }
    const int code = bench::wait_child(receiver, seconds + 60);
    std::ifstream in(out);
    std::string word;
    in >> word >> r.received >> word >> r.lost;
    std::vector<double> us;
    for (double v; in >> v;) us.push_back(v);
    std::remove(out.c_str());
    if (!us.empty()) r.latency = bench::stats_of(us);
    r.lost = r.written - r.received;  // the tail lost too, not only gaps between frames
    r.ok = code == 0 && r.written > 0;
    return r;
}

// ---- measurements -------------------------------------------------------------------------

// Appends `count` one-way latencies (µs, RTT/2) after `warmup` unmeasured round trips.
bool ping_block(Side& side, uint64_t& seq, int count, int warmup, std::vector<double>& one_way_us)
{
    for (int i = 0; i < warmup + count; ++i) {
        const uint64_t mine = ++seq;
        const auto t0 = Clock::now();
        bool answered = false;
        for (int tries = 0; !answered; ++tries) {
            if (tries == (i < warmup ? 20 : 1)) return false;  // a reply can be lost only before both sides matched
            if (!side.write(mine)) continue;
            const auto deadline = Clock::now() + 1s;
            while (!answered && Clock::now() < deadline) {
                if (side.wait(100ms)) side.take([&](uint64_t s) { answered = answered || s == mine; });
            }
        }
        if (i >= warmup) one_way_us.push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count() / 2);
    }
    return true;
}

using bench::Rate;

Rate cpm_throughput(int domain, const std::string& mode, size_t size, int seconds)
{
    const std::string out = "/tmp/bench_large_sub_" + std::to_string(getpid());
    auto sub = bench::spawn({cpm::sibling_executable("bench_large"), "--role", "sub", "--mode", mode, "--size", std::to_string(size),
                             "--domain", std::to_string(domain), "--seconds", std::to_string(seconds + 60)},
                            {}, out);
    Rate r;
    {
        cpm::Participant participant(options_for(domain, mode));
        auto side = make_side(participant, mode, size, "large_stream", "large_ready", true);
        if (!side->wait(20s)) return r;  // the subscriber's "ready"
        side->take([](uint64_t) {});
        const auto end = Clock::now() + std::chrono::seconds(seconds);
        while (Clock::now() < end) {
            if (side->write(r.written)) ++r.written;
        }
        for (int i = 0; i < 100 && !side->write(kEndMarker); ++i) {
        }
        // With data sharing the samples live in the writer's pool: it must stay until read.
        side->wait_acknowledged();
    }
    const int code = bench::wait_child(sub, seconds + 90);
    std::string word;
    double secs = 0;
    std::ifstream(out) >> word >> r.received >> word >> r.lost >> word >> secs;
    std::remove(out.c_str());
    r.rate = secs > 0 ? double(r.received) / secs : 0;
    r.ok = code == 0 && r.received == r.written && r.lost == 0;
    return r;
}

/// Cyclone's shared-memory path for the run: iox-roudi with chunks for both frame sizes, and
/// Cyclone's loopback file with SharedMemory enabled. `missing` says why it is not there
/// (empty when it runs). RouDi is stopped last (it ends its clients with it).
class CycloneSharedMemory
{
public:
    CycloneSharedMemory()
    {
        char dir[] = "/tmp/bench_large_iox.XXXXXX";
        dir_ = ::mkdtemp(dir);
        std::ofstream(dir_ + "/roudi.toml") << "[general]\nversion = 1\n\n[[segment]]\n\n"
                                            << "[[segment.mempool]]\nsize = " << sizeof(BenchFrame307k) + 64 << "\ncount = 16\n\n"
                                            << "[[segment.mempool]]\nsize = " << sizeof(BenchFrame1M) + 64 << "\ncount = 16\n";
        std::string xml = cpm::read_text_file(bench::cyclone_loopback_xml(), "Cyclone DDS configuration");
        const auto end = xml.find("</Domain>");
        if (end == std::string::npos) {
            missing = bench::cyclone_loopback_xml() + " has no </Domain>";
            return;
        }
        xml.insert(end, "  <SharedMemory><Enable>true</Enable><LogLevel>warn</LogLevel></SharedMemory>\n  ");
        std::ofstream(dir_ + "/cyclone-shm.xml") << xml;
        const std::string roudi = cpm::program_on_path("iox-roudi");
        if (roudi.empty()) {
            missing = "iox-roudi is not installed (Debian's iceoryx)";
            return;
        }
        roudi_.emplace(cpm::ProcessOptions{.argv = {roudi, "-c", dir_ + "/roudi.toml"}, .stderr_path = dir_ + "/roudi.err",
                                           .capture_stdout = true, .die_with_parent = true});
        const auto deadline = Clock::now() + 10s;
        std::string last;
        while (Clock::now() < deadline) {
            pollfd out{roudi_->stdout_fd(), POLLIN, 0};
            if (::poll(&out, 1, 100) <= 0) continue;
            const auto line = roudi_->read_line();
            if (!line) break;
            if (line->find("RouDi is ready for clients") != std::string::npos) return;
            if (!line->empty()) last = *line;
        }
        // Its last words (colour codes taken out), from stderr or else stdout.
        std::ifstream err(dir_ + "/roudi.err");
        for (std::string line; std::getline(err, line);) {
            if (!line.empty()) last = line;
        }
        last = std::regex_replace(last, std::regex("\x1b\\[[0-9;]*m"), "");
        missing = "iox-roudi did not come up within 10 s (" + last + "; another RouDi on this host?)";
        roudi_->stop();
        roudi_.reset();
    }
    ~CycloneSharedMemory()
    {
        if (roudi_) {
            roudi_->signal(SIGINT);  // it removes its shared memory and files
            if (!roudi_->wait(10s)) roudi_->stop();
        }
        std::filesystem::remove_all(dir_);
    }
    CycloneSharedMemory(const CycloneSharedMemory&) = delete;
    CycloneSharedMemory& operator=(const CycloneSharedMemory&) = delete;
    std::string env() const { return "CYCLONEDDS_URI=file://" + dir_ + "/cyclone-shm.xml"; }

    std::string missing;

private:
    std::string dir_;
    std::optional<cpm::ChildProcess> roudi_;
};

Rate cyclone_throughput(int domain, size_t size, int seconds)
{
    return bench::cyclone_pub_sub(domain, size - 28, seconds, {"--type", "blob"}, {"--type", "blob", "--touch"});
}

const char* kHelp =
    "usage: bench_large [--count 500] [--seconds 3] [--sizes 307200,1048576] [--domain 220]\n"
    "One-way latency and throughput of large samples between two processes: cpm over UDP only, its shared-memory\n"
    "transport, data sharing and written and read in place, against Cyclone DDS doing the same work (every byte read).\n"
    "  --count N      round trips per case and size, in 10 alternating blocks (at least 10)\n"
    "  --seconds S    how long each throughput case writes\n"
    "  --sizes A,B    each 307200 or 1048576 (the plain frame types)\n"
    "  uses domains D to D+5; the last two are Cyclone DDS's (UDP, shared memory), at most 232\n"
    "Cyclone's shared memory needs iox-roudi (Debian's iceoryx): started for the run, stopped after it\n"
    "       bench_large --camera [--hz 30] [--seconds 3] [--link loopback|veth] [--domain 220]\n"
    "  --camera       a camera's stream instead: 307,200 B frames at --hz with cameraFrame's QoS,\n"
    "                 latency and frames lost, on this host and (--link veth) to a second host: a\n"
    "                 network namespace joined by a veth pair (root)\n"
    "(--role pong|sub|camera --mode MODE --size B --interface A --peer B: the processes it starts)\n";

int run(int argc, char** argv)
{
    const auto flags = cpm::cli::parse_flags(argc, argv,
                                             {{"--count", true}, {"--seconds", true}, {"--sizes", true}, {"--domain", true},
                                              {"--role", true}, {"--mode", true}, {"--size", true}, {"--camera", false},
                                              {"--hz", true}, {"--link", true}, {"--interface", true}, {"--peer", true}},
                                             "bench_large");
    const std::string role = flags.get("--role", "main");
    const int domain = int(cpm::cli::parse_integer("--domain", flags.get("--domain", "220"), 0, 232));
    const int seconds = int(cpm::cli::parse_integer("--seconds", flags.get("--seconds", role == "main" ? "3" : "60"), 1, 86400));
    if (role == "pong" || role == "sub") {
        std::signal(SIGTERM, [](int) { g_stop = true; });
        const std::string mode = flags.get("--mode", "shm");
        const size_t size = size_t(cpm::cli::parse_integer("--size", flags.get("--size", "1048576"), 307200, 1048576));
        if (role == "pong") return pong(domain, mode, size);
        return subscribe(domain, mode, size, seconds);
    }
    if (role == "camera") {
        bench::set_link_end(flags.get("--interface"), flags.get("--peer"));
        return camera_receive(domain, seconds);
    }
    if (role != "main") throw cpm::cli::UsageError("bench_large: --role '" + role + "' is none of main, pong, sub, camera");
    const std::string link = flags.get("--link", "loopback");
    if (link != "loopback" && link != "veth") throw cpm::cli::UsageError("bench_large: --link '" + link + "' is neither loopback nor veth");
    if (flags.has("--camera")) {
        const int hz = int(cpm::cli::parse_integer("--hz", flags.get("--hz", "30"), 1, 1000));
        bench::print_machine("a camera's stream: 307,200 B frames at " + std::to_string(hz) + " Hz for " + std::to_string(seconds) +
                             " s with cameraFrame's QoS (best effort, keep last 1); latency from the frame's stamp to its arrival (µs)");
        bench::print_header("camera frames, 307200 B at " + std::to_string(hz) + " Hz");
        const CameraStream here = camera_stream(domain, hz, seconds, false);
        bench::print_row("cpm, same host (shared memory)", here.latency);
        std::printf("    written %llu, received %llu, lost %llu\n", (unsigned long long)here.written, (unsigned long long)here.received,
                    (unsigned long long)here.lost);
        if (link != "veth") return here.ok ? 0 : 1;
        (void)bench::use_veth_link();  // after the same-host case, which runs as a lab on one host does
        const CameraStream far = camera_stream(domain + 1, hz, seconds, true);
        bench::print_row("cpm, across the veth link (UDP)", far.latency);
        std::printf("    written %llu, received %llu, lost %llu\n", (unsigned long long)far.written, (unsigned long long)far.received,
                    (unsigned long long)far.lost);
        if (here.ok && far.ok) {
            bench::record_latency("large", "camera frame 307200 B at " + std::to_string(hz) + " Hz across a veth link", far.latency,
                                  "cpm, same host (shared memory)", here.latency, 0);
            bench::record({"large", "camera frames lost across a veth link, of " + std::to_string(far.written), "frames", double(far.lost),
                           "cpm, same host (shared memory)", double(here.lost)});
        }
        return here.ok && far.ok ? 0 : 1;
    }
    if (domain + 5 > 232) {
        throw cpm::cli::UsageError("bench_large: --domain " + std::to_string(domain) + ": the run uses domains " + std::to_string(domain) +
                                   " to " + std::to_string(domain + 5) + ", and Cyclone DDS (the last two) takes at most 232");
    }
    const int count = int(cpm::cli::parse_integer("--count", flags.get("--count", "500"), 10, 10'000'000));
    std::vector<size_t> sizes;
    for (long long size : bench::integer_list("--sizes", flags.get("--sizes", "307200,1048576"), 307200, 1048576)) {
        if (size != 307200 && size != 1048576)
            throw cpm::cli::UsageError("bench_large: --sizes: " + std::to_string(size) + " is neither 307200 nor 1048576 (the plain frame types)");
        sizes.push_back(size_t(size));
    }

    bench::print_machine("one way: reliable keep-last 1, " + std::to_string(count) +
                         " round trips in 10 alternating blocks, one-way = RTT/2 (µs); throughput: reliable keep-all, "
                         "a window of " + std::to_string(kWindow) + " samples, " + std::to_string(seconds) +
                         " s; cpm on its default transports (shared memory + loopback UDP), Cyclone DDS on loopback UDP and "
                         "on its shared memory (iceoryx)");
    const CycloneSharedMemory iceoryx;
    if (!iceoryx.missing.empty()) std::printf("Cyclone's shared memory left out: %s\n", iceoryx.missing.c_str());
    struct Mode
    {
        std::string name, label;
    };
    const std::vector<Mode> modes{{"udp", "cpm, UDP only (BenchBlob)"},
                                  {"shm", "cpm, shared-memory transport (BenchBlob)"},
                                  {"sharing", "cpm, data_sharing (BenchBlob)"},
                                  {"in_place", "cpm, data_sharing + in place (plain BenchFrame)"}};
    const std::string cyclone_label = "Cyclone DDS, same work (BenchBlob, UDP)";
    const std::string cyclone_shm_label = "Cyclone DDS, shared memory (loaned BenchFrame)";
    int exit_code = 0;
    for (size_t size : sizes) {
        const std::string sized = std::to_string(size) + " B";
        bench::print_header("one-way latency, " + sized);
        std::vector<cpm::ChildProcess> pongs;
        std::vector<std::unique_ptr<cpm::Participant>> participants;
        std::vector<std::unique_ptr<Side>> sides;
        for (size_t k = 0; k < modes.size(); ++k) {
            const int d = domain + int(k);
            pongs.push_back(bench::spawn_self({"--role", "pong", "--mode", modes[k].name, "--size", std::to_string(size), "--domain",
                                               std::to_string(d)}));
            participants.push_back(std::make_unique<cpm::Participant>(options_for(d, modes[k].name)));
            sides.push_back(make_side(*participants.back(), modes[k].name, size, "large_ping", "large_pong", false));
        }
        const int cyclone_domain = domain + int(modes.size());
        pongs.push_back(bench::spawn({cpm::sibling_executable("cyclone_bench"), "pong", "--type", "blob", "--touch", "--domain",
                                      std::to_string(cyclone_domain)},
                                     {bench::cyclone_loopback_env()}, ""));
        // Cyclone's two paths after cpm's cases: on UDP, and (when it runs) on shared memory.
        const bool shm = iceoryx.missing.empty();
        const int cyclone_shm_domain = cyclone_domain + 1;
        if (shm) {
            pongs.push_back(bench::spawn({cpm::sibling_executable("cyclone_bench"), "pong", "--type", "frame", "--size", std::to_string(size),
                                          "--loan", "--touch", "--domain", std::to_string(cyclone_shm_domain)},
                                         {iceoryx.env()}, ""));
        }
        const size_t cases = modes.size() + 1 + (shm ? 1 : 0);
        std::vector<std::vector<double>> samples(cases);
        std::vector<bool> ok(cases, true);
        std::vector<uint64_t> seqs(modes.size(), 0);
        for (size_t k = 0; k < modes.size(); ++k) ok[k] = sides[k]->connected();
        {
            // Warm across the blocks, as the cpm sides.
            std::vector<std::unique_ptr<bench::CyclonePinger>> cyclone;
            cyclone.push_back(std::make_unique<bench::CyclonePinger>(cyclone_domain, size - 28, std::vector<std::string>{"--type", "blob", "--touch"}));
            if (shm) {
                cyclone.push_back(std::make_unique<bench::CyclonePinger>(
                    cyclone_shm_domain, size, std::vector<std::string>{"--type", "frame", "--loan", "--touch"}, iceoryx.env()));
            }
            for (int block = 0; block < 10; ++block) {
                const int warmup = block == 0 ? 50 : 5;
                for (size_t k = 0; k < modes.size(); ++k) {
                    if (ok[k]) ok[k] = ping_block(*sides[k], seqs[k], count / 10, warmup, samples[k]);
                }
                for (size_t c = 0; c < cyclone.size(); ++c) {
                    if (ok[modes.size() + c]) ok[modes.size() + c] = cyclone[c]->block(count / 10, warmup, samples[modes.size() + c]);
                }
            }
        }  // the Cyclone pingers end before RouDi can
        sides.clear();
        participants.clear();
        for (auto& p : pongs) p.signal(SIGTERM);
        for (auto& p : pongs) bench::wait_child(p, 10);

        std::map<std::string, bench::Stats> latency;
        for (size_t k = 0; k < cases; ++k) {
            const std::string name = k < modes.size() ? modes[k].name : k == modes.size() ? "cyclone" : "cyclone_shm";
            const std::string label = k < modes.size() ? modes[k].label : k == modes.size() ? cyclone_label : cyclone_shm_label;
            if (!ok[k]) {
                std::printf("%-48s FAILED after %zu round trips\n", label.c_str(), samples[k].size());
                exit_code = 1;
                continue;
            }
            latency[name] = bench::stats_of(samples[k]);
            bench::print_row(label, latency[name]);
        }
        for (const auto& m : modes) {
            // Each path against Cyclone's of its class; 1 MiB one way no slower than Cyclone's.
            const bool udp = m.name == "udp";
            const std::string peer = udp ? "cyclone" : "cyclone_shm";
            if (!latency.count(m.name) || !latency.count(peer)) continue;
            bench::print_ratio(m.name + " / Cyclone" + (udp ? " on UDP" : " on shared memory"), latency[m.name], latency[peer]);
            bench::record_latency("large", sized + " one-way, " + m.label.substr(5), latency[m.name], udp ? cyclone_label : cyclone_shm_label,
                                  latency[peer], size >= 1048576 ? 1.0 : 0);
        }
        if (!shm) std::printf("(no verdict for the shared-memory paths: %s)\n", iceoryx.missing.c_str());
        if (latency.count("shm") && latency.count("in_place"))
            bench::print_ratio("in_place / shared-memory transport", latency["in_place"], latency["shm"]);

        std::printf("\nthroughput, %s          samples/s        MB/s   written  received  lost\n", sized.c_str());
        std::map<std::string, Rate> rates;
        for (size_t k = 0; k <= modes.size(); ++k) {
            const bool cyclone = k == modes.size();
            const std::string name = cyclone ? "cyclone" : modes[k].name;
            Rate r = cyclone ? cyclone_throughput(cyclone_domain, size, seconds) : cpm_throughput(domain + int(k), name, size, seconds);
            std::printf("%-48s %10.0f %10.0f %9llu %9llu %5llu  %s\n", (cyclone ? cyclone_label : modes[k].label).c_str(), r.rate,
                        r.rate * double(size) / 1e6, (unsigned long long)r.written, (unsigned long long)r.received,
                        (unsigned long long)r.lost, r.ok ? "ok" : "INCOMPLETE");
            if (!r.ok) exit_code = 1;
            rates[name] = r;
        }
        for (const auto& m : modes) {
            if (!rates[m.name].ok || !rates["cyclone"].ok) continue;
            const double ratio = rates[m.name].rate / rates["cyclone"].rate;
            std::printf("%-48s %.2f\n", (m.name + " / Cyclone throughput").c_str(), ratio);
            bench::record({"large", sized + " throughput, " + m.label.substr(5), "samples/s", rates[m.name].rate, cyclone_label,
                           rates["cyclone"].rate, "", -1});
        }
    }
    return exit_code;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "bench_large", kHelp, run); }
