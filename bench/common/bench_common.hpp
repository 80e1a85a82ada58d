#pragma once
#include <cpm/ChildProcess.hpp>
#include <cpm/Participant.hpp>

// What every benchmark here shares: statistics printed the same way, child processes, the
// Cyclone configuration that pins ddsperf to loopback, and the machine description. Flags are
// cpm's own (cpm::cli, cpm/CommandLine.hpp), as in every cpm program.
#include <cstdint>
#include <string>
#include <vector>

namespace bench {

struct Stats
{
    size_t n = 0;
    double min = 0, p50 = 0, p90 = 0, p99 = 0, max = 0;  // microseconds
};

/// min, p50, p90, p99 and max of samples given in microseconds, each by cpm::percentile (the
/// nearest rank: min is p0, max is p100).
Stats stats_of(const std::vector<double>& samples_us);

/// "n min p50 p90 p99 max" header and one row; ratio rows compare p50/p99.
void print_header(const std::string& what);
void print_row(const std::string& label, const Stats& s);
void print_ratio(const std::string& label, const Stats& ours, const Stats& reference);

/// Machine and settings, printed once at the top.
void print_machine(const std::string& settings);

/// Starts this program again with `args`.
cpm::ChildProcess spawn_self(const std::vector<std::string>& args);
/// Starts a program with args and extra environment, stdout to `out_path` (and stderr to
/// `err_path` when given).
cpm::ChildProcess spawn(const std::vector<std::string>& argv, const std::vector<std::string>& env, const std::string& out_path,
                        const std::string& err_path = "");
/// Waits for a child's end; returns its exit code (-1 if a signal ended it). Stops it after timeout_s.
int wait_child(cpm::ChildProcess& child, double timeout_s);

/// While it lives, `count` processes (this program again with `--role busy`, see
/// spin_if_asked) spin at normal priority: a busy loop on each core (0: none).
class BusyLoops
{
public:
    explicit BusyLoops(unsigned count);
    ~BusyLoops();
    BusyLoops(const BusyLoops&) = delete;
    BusyLoops& operator=(const BusyLoops&) = delete;
    /// One per core of this machine.
    static unsigned every_core();

private:
    std::vector<cpm::ChildProcess> spinners_;
};
/// Spins for ever when `role` is "busy" (the process BusyLoops starts); returns otherwise.
void spin_if_asked(const std::string& role);

/// CYCLONEDDS_URI=... for loopback only, unicast discovery, no multicast.
std::string cyclone_loopback_env();
/// That configuration file's path (share/cyclonedds-localhost.xml).
std::string cyclone_loopback_xml();

/// Two hosts on one machine: network namespaces joined by a veth pair (root only), for the cases
/// that measure what goes between hosts. Made by use_veth_link(); gone when the program exits.
class VethLink
{
public:
    VethLink();  ///< throws cpm::Error saying what failed
    ~VethLink();
    VethLink(const VethLink&) = delete;
    VethLink& operator=(const VethLink&) = delete;
    /// The address of side 0 (the publisher's host) or 1 (the subscriber's).
    std::string address(int side) const;
    /// argv run on that side (ip netns exec).
    std::vector<std::string> in(int side, std::vector<std::string> argv) const;
    /// Moves the calling thread (and the threads it starts from now on) to that side.
    void enter(int side) const;
    /// CYCLONEDDS_URI=<CycloneDDS>… for that side: its address, the other side as peer, no multicast.
    std::string cyclone_env(int side) const;

private:
    void remove();
    std::string ns_[2];
    std::string subnet_;
};
/// Makes the link (once) and moves this thread to side 0; every case then runs across it.
const VethLink& use_veth_link();
/// The link when use_veth_link() made one; nullptr: this host, loopback and shared memory.
const VethLink* veth_link();
/// This process's end of the link (its address, the other's), as a lab run gives each process
/// --dds_interface and --dds_initial_peer: side 0 after use_veth_link(), or what a far-side
/// process was told (--interface A --peer B, passed by far_side()). Empty: loopback.
void set_link_end(const std::string& interface, const std::string& peer);
/// Its address and the peer on `o` when there is a link; `o` unchanged otherwise.
void apply_link_end(cpm::ParticipantOptions& o);
/// A helper process of this program for the other end: with a link, run on side 1 and told its
/// end (--interface, --peer); without, `argv` as it is.
std::vector<std::string> far_side(std::vector<std::string> argv);
/// Another program (Cyclone's) for the other end: on side 1 with a link, as it is without.
std::vector<std::string> on_far_side(std::vector<std::string> argv);
/// CYCLONEDDS_URI for Cyclone on this side (side 0 with a link, else loopback) or the far side.
std::string cyclone_env_here();
std::string cyclone_env_far();

/// Cyclone's side of a ping-pong: one `cyclone_bench ping --blocks` (loopback UDP, or this side
/// of the link) against the pong on `domain`, kept running between blocks as cpm's pingers are.
/// `extra`: more arguments (e.g. --type blob).
class CyclonePinger
{
public:
    /// `env`: its environment ("CYCLONEDDS_URI=…"); empty: Cyclone on loopback UDP (or the veth link).
    CyclonePinger(int domain, size_t size, const std::vector<std::string>& extra = {}, const std::string& env = "");
    /// Ends its input and lets it leave on its own (Cyclone's shared memory keeps files of a
    /// process that was killed).
    ~CyclonePinger();
    CyclonePinger(const CyclonePinger&) = delete;
    CyclonePinger& operator=(const CyclonePinger&) = delete;
    /// `warmup` round trips, then `count` whose one-way latencies (µs) are appended. False when the
    /// block did not complete (the process then has ended: every later block is false too).
    bool block(int count, int warmup, std::vector<double>& one_way_us);

private:
    cpm::ChildProcess ping_;
    bool ok_ = true;
};

/// What one throughput run measured (cyclone_bench's pub and sub report these too).
struct Rate
{
    double rate = 0;  ///< samples/s, first to last arrival
    uint64_t received = 0, lost = 0, written = 0;
    bool ok = false;  ///< both ended well and every written sample arrived, none lost
};
/// `cyclone_bench sub` and `pub` on `domain` (loopback UDP, or across veth_link()) for `seconds`; `pub_extra` and
/// `sub_extra` are added to their arguments (--batch, --listener, --type blob).
Rate cyclone_pub_sub(int domain, size_t size, int seconds, const std::vector<std::string>& pub_extra,
                            const std::vector<std::string>& sub_extra);

/// Whether this run uses Fast DDS data sharing (BENCH_DATA_SHARING=1), for cpm and raw alike;
/// off by default, as in cpm.
bool data_sharing();

/// One measured figure beside its peer from the same run, for `./lab bench --json FILE` and the
/// table `./lab bench` ends with. `met`: whether `target` (in words) is reached; unset when the
/// figure has no target.
struct Figure
{
    std::string bench;      ///< the program, e.g. "latency"
    std::string what;       ///< the case, e.g. "100 B one-way p50"
    std::string unit;       ///< e.g. "µs", "samples/s"
    double cpm = 0;
    std::string peer;       ///< e.g. "raw Fast DDS (listener pong)"; empty: no peer
    double peer_value = 0;
    std::string target;     ///< e.g. "<= 1.05x peer"; empty: none
    int met = -1;           ///< 1 met, 0 not met, -1 no target
};
/// Appends the figure as one JSON line ({"bench", "case", "unit", "cpm", "peer", "peer_value",
/// "ratio", "target", "met"}) to the file $CPM_BENCH_JSON names; nothing when it is unset.
void record(const Figure& f);
/// Records the p50 and p99 of `ours` against `reference` (µs); `target_p50` is the largest p50
/// ratio that meets the target (0: no target).
void record_latency(const std::string& bench, const std::string& what, const Stats& ours, const std::string& peer, const Stats& reference,
                    double target_p50 = 0);

/// A secured lab for the benchmarks (cpm security init + one node allowed every topic) in a
/// fresh folder, removed at the end; `node` is the node's security folder.
struct SecuredLab
{
    std::string dir, node;
    SecuredLab();
    ~SecuredLab();
    SecuredLab(const SecuredLab&) = delete;
    SecuredLab& operator=(const SecuredLab&) = delete;
};

/// A flag's list of whole numbers ("--sizes 100,65536"): cpm::cli::split_list, each item read
/// by cpm::cli::parse_integer within [min, max]; a UsageError names the flag and the item.
std::vector<long long> integer_list(const std::string& flag, const std::string& text, long long min, long long max);

}  // namespace bench
