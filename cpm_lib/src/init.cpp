#include <cpm/init.hpp>

#include <cpm/CommandLine.hpp>
#include <cpm/Error.hpp>
#include <cpm/Security.hpp>

#include "lab_clock.hpp"
#include "realtime_internal.hpp"

#include <openssl/crypto.h>

#include <arpa/inet.h>
#include <ifaddrs.h>
#include <netinet/in.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <optional>
#include <set>

namespace cpm {
namespace {

std::mutex g_settings_mutex;
std::optional<InitSettings> g_settings;

long long parse_integer(const std::string& text, const std::string& source)
{
    if (text.empty()) throw Error(source + ": expected a number, got an empty value");
    char* end = nullptr;
    errno = 0;
    const long long value = std::strtoll(text.c_str(), &end, 10);
    if (errno != 0 || *end != '\0') throw Error(source + ": '" + text + "' is not a whole number");
    return value;
}

bool parse_bool(const std::string& text, const std::string& source)
{
    if (text == "true" || text == "1" || text == "yes" || text == "on") return true;
    if (text == "false" || text == "0" || text == "no" || text == "off") return false;
    throw Error(source + ": '" + text + "' is not a boolean (true/false)");
}

std::string basename_of(const char* path)
{
    if (path == nullptr) return "cpm_node";
    const char* slash = std::strrchr(path, '/');
    return slash ? slash + 1 : path;
}

// The value of `--name=value` or `--name value`; advances i past a separate value.
std::optional<std::string> flag_value(int argc, const char* const argv[], int& i, const std::string& name)
{
    const std::string arg = argv[i];
    const std::string prefix = "--" + name;
    if (arg.rfind(prefix, 0) != 0) return std::nullopt;
    if (arg.size() == prefix.size()) {
        if (i + 1 >= argc) throw Error("flag " + prefix + ": missing value");
        return std::string(argv[++i]);
    }
    if (arg[prefix.size()] != '=') return std::nullopt;  // a longer, different flag
    return arg.substr(prefix.size() + 1);
}

std::string security_from_environment()
{
    const char* s = std::getenv("CPM_SECURITY");
    return s ? s : "";
}

}  // namespace

bool is_init_flag(const std::string& flag, bool& takes_value)
{
    static const std::pair<const char*, bool> kFlags[] = {
        {"--dds_domain", true},       {"--node_id", true},           {"--dds_interface", true},
        {"--dds_initial_peer", true}, {"--dds_discovery_server", true}, {"--simulated_time", false},
        {"--security", true},         {"--dds_shared_memory", true},  {"--dds_lease", true},
        {"--realtime", false}};
    for (const auto& [name, value] : kFlags) {
        if (flag == name) {
            takes_value = value;
            return true;
        }
    }
    return false;
}

int checked_domain_id(long long domain_id, const std::string& source)
{
    if (domain_id < 0 || domain_id > 232) {
        throw Error(source + ": DDS domain id " + std::to_string(domain_id) +
                    " is outside 0..232 (Fast DDS would accept it and then discover nobody)");
    }
    return static_cast<int>(domain_id);
}

std::chrono::milliseconds checked_lease(std::chrono::milliseconds lease, const std::string& source, const std::string& text)
{
    if (lease < std::chrono::seconds(1) || lease > std::chrono::hours(1)) {
        throw Error(source + ": " + (text.empty() ? std::to_string(lease.count()) + "ms" : text) +
                    " is outside 1s..1h (how long the others wait for a silent participant before dropping it)");
    }
    return lease;
}

namespace {

std::chrono::milliseconds parse_lease(const std::string& text, const std::string& source)
{
    return checked_lease(std::chrono::milliseconds(cli::parse_duration(source, text) / 1'000'000), source, text);
}

}  // namespace

InitSettings parse_init_settings(int argc, const char* const argv[], const char* env_domain)
{
    InitSettings settings;
    settings.node_id = basename_of(argc > 0 ? argv[0] : nullptr);
    if (env_domain != nullptr && *env_domain != '\0') {
        settings.domain_id = checked_domain_id(parse_integer(env_domain, "CPM_DOMAIN_ID"), "CPM_DOMAIN_ID");
    }
    if (const char* shm = std::getenv("CPM_SHARED_MEMORY"); shm != nullptr && *shm != '\0') {
        settings.shared_memory = parse_bool(shm, "CPM_SHARED_MEMORY");
        settings.shared_memory_chosen = true;
    }
    if (const char* lease = std::getenv("CPM_DDS_LEASE"); lease != nullptr && *lease != '\0') {
        settings.lease = parse_lease(lease, "CPM_DDS_LEASE");
    }
    if (const char* realtime = std::getenv("CPM_REALTIME"); realtime != nullptr && *realtime != '\0') {
        settings.realtime = parse_realtime(realtime, "CPM_REALTIME");
    }
    for (int i = 1; i < argc; ++i) {
        if (std::strcmp(argv[i], "--realtime") == 0) {
            settings.realtime = Realtime::on;
        } else if (std::strncmp(argv[i], "--realtime=", 11) == 0) {
            settings.realtime = parse_realtime(argv[i] + 11, "--realtime");
        } else if (std::strcmp(argv[i], "--simulated_time") == 0) {
            settings.simulated_time = true;
        } else if (auto v = flag_value(argc, argv, i, "simulated_time")) {
            settings.simulated_time = parse_bool(*v, "--simulated_time");
        } else if (auto v = flag_value(argc, argv, i, "dds_domain")) {
            settings.domain_id = checked_domain_id(parse_integer(*v, "--dds_domain"), "--dds_domain");
        } else if (auto v = flag_value(argc, argv, i, "node_id")) {
            if (v->empty()) throw Error("--node_id: empty value");
            settings.node_id = *v;
        } else if (auto v = flag_value(argc, argv, i, "dds_interface")) {
            if (v->empty()) throw Error("--dds_interface: empty value");
            settings.interfaces.push_back(*v);
        } else if (auto v = flag_value(argc, argv, i, "dds_initial_peer")) {
            if (v->empty()) throw Error("--dds_initial_peer: empty value");
            settings.initial_peers.push_back(*v);
        } else if (auto v = flag_value(argc, argv, i, "dds_discovery_server")) {
            if (v->empty()) throw Error("--dds_discovery_server: empty value");
            settings.discovery_server = *v;
        } else if (auto v = flag_value(argc, argv, i, "dds_shared_memory")) {
            settings.shared_memory = parse_bool(*v, "--dds_shared_memory");
            settings.shared_memory_chosen = true;
        } else if (auto v = flag_value(argc, argv, i, "dds_lease")) {
            settings.lease = parse_lease(*v, "--dds_lease");
        } else if (auto v = flag_value(argc, argv, i, "security")) {
            if (v->empty()) throw Error("--security: empty value (a node's security folder, LAB/nodes/NAME)");
            settings.security = *v;
        }
    }
    return settings;
}

void check_local_interface(const std::string& interface, const std::string& source)
{
    ifaddrs* list = nullptr;
    if (getifaddrs(&list) != 0) return;  // cannot tell: leave it to Fast DDS
    std::set<std::string> known;
    bool found = false;
    for (ifaddrs* a = list; a != nullptr; a = a->ifa_next) {
        std::string entry = a->ifa_name;
        if (a->ifa_addr != nullptr && a->ifa_addr->sa_family == AF_INET) {
            char text[INET_ADDRSTRLEN] = {};
            inet_ntop(AF_INET, &reinterpret_cast<const sockaddr_in*>(a->ifa_addr)->sin_addr, text, sizeof text);
            found = found || interface == text;
            entry += std::string(" (") + text + ")";
        }
        found = found || interface == a->ifa_name;
        known.insert(entry);
    }
    freeifaddrs(list);
    if (found) return;
    std::string names;
    for (const auto& k : known) names += (names.empty() ? "" : ", ") + k;
    throw Error(source + ": '" + interface + "' is neither an interface nor an IPv4 address of this host (it has: " +
                names + ")");
}

void init(int argc, char* argv[])
{
    InitSettings settings;
    try {
        settings = parse_init_settings(argc, argv, std::getenv("CPM_DOMAIN_ID"));
        for (const auto& interface : settings.interfaces) check_local_interface(interface, "--dds_interface");
        if (settings.security.empty()) settings.security = security_from_environment();
        if (!settings.security.empty()) {
            (void)security::node_files(settings.security);  // every file there, or say which is not
            // Before anything starts OpenSSL: it must not free itself at exit under Fast DDS's
            // threads (see ParticipantCore).
            OPENSSL_init_crypto(OPENSSL_INIT_NO_ATEXIT, nullptr);
        }
        detail::start_realtime(settings.realtime, settings.node_id);
    } catch (const cli::UsageError&) {
        throw;
    } catch (const Error& e) {
        throw cli::UsageError(e.what());
    }
    detail::use_simulated_clock(settings.simulated_time);
    std::lock_guard<std::mutex> lock(g_settings_mutex);
    g_settings = std::move(settings);
}

InitSettings init_settings()
{
    std::lock_guard<std::mutex> lock(g_settings_mutex);
    if (!g_settings) {
        const char* argv0[] = {"cpm_node"};
        g_settings = parse_init_settings(1, argv0, std::getenv("CPM_DOMAIN_ID"));
        g_settings->security = security_from_environment();
    }
    return *g_settings;
}

}  // namespace cpm
