#pragma once
#include <chrono>
#include <string>
#include <vector>

#include <cpm/Realtime.hpp>

namespace cpm {

/// The settings every cpm program shares, read by cpm::init from its command line.
struct InitSettings
{
    int domain_id = 0;                       ///< --dds_domain (or CPM_DOMAIN_ID), 0..232
    std::string node_id;                     ///< --node_id; default: the program's name
    std::vector<std::string> interfaces;     ///< --dds_interface (IPv4 address or interface name)
    std::vector<std::string> initial_peers;  ///< --dds_initial_peer (host or host:port)
    std::string discovery_server;            ///< --dds_discovery_server (host:port)
    bool simulated_time = false;             ///< --simulated_time
    std::string security;                    ///< --security (or CPM_SECURITY): a node's security folder
    bool shared_memory = true;               ///< --dds_shared_memory on|off (or CPM_SHARED_MEMORY)
    bool shared_memory_chosen = false;       ///< whether --dds_shared_memory or CPM_SHARED_MEMORY was given
    /// --dds_lease (or CPM_DDS_LEASE), 1s..1h: how long the others wait for this process's
    /// participants once they fall silent (a crash) before dropping them and what they wrote.
    std::chrono::milliseconds lease{10'000};
    /// --realtime (on), --realtime=required|on|off (or CPM_REALTIME): lock memory, run the timer and
    /// serial-loop threads SCHED_FIFO (see cpm/Realtime.hpp). cpm::init locks the memory and
    /// checks the privileges: with `required`, a UsageError naming what is missing.
    Realtime realtime = Realtime::off;
};

/// Reads cpm's flags (`--flag=value` or `--flag value`) from the command line and
/// CPM_DOMAIN_ID (CPM_SECURITY, CPM_SHARED_MEMORY, CPM_DDS_LEASE, CPM_REALTIME) from the environment; other flags are left to
/// the program.
/// Throws cpm::cli::UsageError (a cpm::Error; cpm's programs exit 2 on it) naming the flag and
/// value when a value is malformed or out of range, or an interface is not on this host.
/// Call before the first Participant is created (the default participant uses these).
void init(int argc, char* argv[]);

/// The settings from the last cpm::init (or from the environment alone if never called).
InitSettings init_settings();

/// Parses settings without touching global state; env_domain is CPM_DOMAIN_ID or nullptr.
InitSettings parse_init_settings(int argc, const char* const argv[], const char* env_domain);

/// Whether `flag` (e.g. "--dds_domain", without "=value") is one of cpm::init's flags; then
/// `takes_value` says whether a separate value follows it (--simulated_time and --realtime stand
/// alone; their value, if any, is given as --realtime=required).
/// Lets programs with flags of their own pass cpm's through.
bool is_init_flag(const std::string& flag, bool& takes_value);

/// Throws cpm::Error naming `source` and the value unless `interface` is the name or an IPv4
/// address of one of this host's network interfaces (then the error lists the ones it has).
void check_local_interface(const std::string& interface, const std::string& source);

/// Checks a DDS domain id: Fast DDS accepts 233 and above but then never discovers anyone.
/// `source` names where the value came from in the error message.
int checked_domain_id(long long domain_id, const std::string& source);

/// Checks a participant's lease (1s..1h; below a second, a busy machine drops live peers).
/// The error names `source` and `text` (the value as given; empty: the milliseconds).
std::chrono::milliseconds checked_lease(std::chrono::milliseconds lease, const std::string& source,
                                        const std::string& text = "");

}  // namespace cpm
