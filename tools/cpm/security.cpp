// cpm security init|add-node: a secured lab's CAs, governance and nodes (the work is in
// cpm::security).
#include "Command.hpp"

#include <cpm/Diagnostics.hpp>
#include <cpm/nodes.hpp>

#include <algorithm>

#include <cpm/Security.hpp>

#include <cstdio>

namespace cpm::tools {
namespace {

const char* kInitHelp =
    "usage: cpm security init DIR [--days N]\n"
    "\n"
    "Makes a secured lab's folder: its identity CA (signs the nodes' certificates), its separate\n"
    "permissions CA (signs the governance and each node's permissions, nothing else) and the signed\n"
    "governance: on every domain, every topic authenticated, access-controlled and encrypted, and\n"
    "discovery encrypted. Keep DIR private: it holds both CA keys. Refuses a DIR that has a lab.\n"
    "\n"
    "  --days N    validity of both CAs (default 3650)\n"
    "\n"
    "Then: cpm security add-node DIR NAME --publish ... --subscribe ...\n";

const char* kAddNodeHelp =
    "usage: cpm security add-node DIR NAME [--kind KIND] [--publish T1,T2,...] [--subscribe T3,...] [--days N]\n"
    "\n"
    "Issues node NAME of the lab in DIR: a key, a certificate from the lab's identity CA and\n"
    "permissions signed by its permissions CA, into DIR/nodes/NAME/. Copy that folder (only that\n"
    "one) to the machine the node runs on and start the node with --security DIR/nodes/NAME (or\n"
    "CPM_SECURITY=DIR/nodes/NAME). Topics may use the wildcards * and ?. Every node may also use\n"
    "what each cpm process uses by itself: it publishes log, readyStatus and parameterRequest and\n"
    "subscribes logLevel, parameter and systemTrigger.\n"
    "\n"
    "  --kind KIND         grant what cpm's program KIND uses (cpm_history, fsm_node, vehicle_bridge,\n"
    "                      ...; a wrong one lists them all); --publish/--subscribe add to it\n"
    "  --publish T,...     topics it may write\n"
    "  --subscribe T,...   topics it may read (through the history service too)\n"
    "  --days N            validity of its certificate and permissions (default 3650)\n"
    "\n"
    "Examples: cpm security add-node lab viewer --subscribe vehicleState,vehicleObservation\n"
    "          cpm security add-node lab car3_fsm --kind fsm_node\n";

int days_flag(const ParsedArgs& parsed, const std::string& command)
{
    return parsed.has("--days") ? int(cpm::cli::parse_integer(command + ": --days", parsed.get("--days"), 1, 36500)) : 3650;
}

int init(const std::vector<std::string>& args)
{
    const std::string command = "cpm security init";
    const auto parsed = parse_args(args, {{"--days", true}}, command);
    const std::string dir = only_positional(parsed, command, "DIR (the lab's security folder)");
    cpm::security::init_lab(dir, days_flag(parsed, command));
    std::printf("cpm security: lab made in %s (identity CA, permissions CA, governance); add nodes with\n"
                "  cpm security add-node %s NAME --publish ... --subscribe ...\n",
                dir.c_str(), dir.c_str());
    return 0;
}

int add_node(const std::vector<std::string>& args)
{
    const std::string command = "cpm security add-node";
    const auto parsed = parse_args(args, {{"--kind", true}, {"--publish", true, true}, {"--subscribe", true, true}, {"--days", true}}, command);
    if (parsed.positional.size() != 2) throw UsageError(command + ": expected DIR NAME (the lab's security folder and the node's name)");
    cpm::security::Grant grant;
    if (parsed.has("--kind")) {
        const std::string kind = parsed.get("--kind");
        const auto known = cpm::nodes::kinds();
        if (std::find(known.begin(), known.end(), kind) == known.end()) {
            std::string list;
            for (const auto& k : known) list += (list.empty() ? "" : ", ") + k;
            const auto meant = cpm::did_you_mean(kind, known);
            throw UsageError(command + ": --kind " + kind + ": no such program" + (meant ? " (did you mean " + *meant + "?)" : std::string()) +
                             "; known: " + list);
        }
        grant.publish = cpm::nodes::find(kind).publish;
        grant.subscribe = cpm::nodes::find(kind).subscribe;
    }
    for (const auto& v : parsed.all("--publish")) {
        for (auto& t : split_list("--publish", v)) grant.publish.push_back(t);
    }
    for (const auto& v : parsed.all("--subscribe")) {
        for (auto& t : split_list("--subscribe", v)) grant.subscribe.push_back(t);
    }
    grant.days = days_flag(parsed, command);
    const std::string node = cpm::security::add_node(parsed.positional[0], parsed.positional[1], grant);
    std::printf("cpm security: node %s issued in %s; start it with --security %s\n", parsed.positional[1].c_str(), node.c_str(),
                node.c_str());
    return 0;
}

}  // namespace

std::vector<Command> security_commands()
{
    return {{.group = "security", .verb = "init", .summary = "make a secured lab's CAs and governance", .help = kInitHelp, .run = init},
            {.group = "security", .verb = "add-node", .summary = "issue a node's certificate and permissions", .help = kAddNodeHelp, .run = add_node}};
}

}  // namespace cpm::tools
