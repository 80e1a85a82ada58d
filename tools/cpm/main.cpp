// cpm — the lab's command line, in the style of `ros2`: `cpm GROUP VERB [flags]`. Each verb
// group lives in its own file; this one only finds the command, and turns errors into a message
// on stderr and an exit code (2 for a wrong command line, 1 for anything else).
#include "Command.hpp"

#include <cpm/CommandLine.hpp>
#include <cpm/init.hpp>

#include <fastrtps/config.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

namespace cpm::tools {

cpm::ParticipantOptions named_participant(const std::string& name)
{
    cpm::ParticipantOptions options = cpm::ParticipantOptions::from_init();
    if (cpm::init_settings().node_id == "cpm") options.name = name;  // "cpm": no --node_id given
    return options;
}

}  // namespace cpm::tools

namespace {

using cpm::cli::UsageError;
using cpm::tools::Command;

std::vector<Command> all_commands()
{
    std::vector<Command> all;
    for (auto group : {cpm::tools::lab_commands, cpm::tools::param_commands, cpm::tools::topic_commands,
                       cpm::tools::fsm_commands, cpm::tools::vehicle_commands, cpm::tools::history_commands,
                       cpm::tools::aruco_commands, cpm::tools::routing_commands, cpm::tools::record_commands,
                       cpm::tools::monitor_commands, cpm::tools::security_commands, cpm::tools::host_commands}) {
        auto more = group();
        all.insert(all.end(), more.begin(), more.end());
    }
    return all;
}

std::string command_name(const Command& c) { return std::string(c.group) + (*c.verb ? std::string(" ") + c.verb : ""); }

/// `cpm --help` (group empty) or `cpm GROUP --help`: the commands with a line each.
std::string overview(const std::vector<Command>& all, const std::string& group)
{
    std::string out = group.empty() ? "usage: cpm COMMAND ...\n\n" : "usage: cpm " + group + " VERB ...\n\n";
    for (const auto& c : all) {
        if (!group.empty() && c.group != group) continue;
        char line[256];
        std::snprintf(line, sizeof line, "  %-16s %s\n", command_name(c).c_str(), c.summary);
        out += line;
    }
    out += group.empty() ? "\nEvery command takes --dds_domain N (or CPM_DOMAIN_ID) and answers --help; cpm --version.\n"
                         : "\n`cpm " + group + " VERB --help` says more.\n";
    return out;
}

/// The command line without cpm::init's flags (which may stand anywhere, before the command too).
std::vector<std::string> command_words(int argc, char** argv, std::vector<std::string>* init_flags = nullptr)
{
    std::vector<std::string> words;
    for (int i = 1; i < argc; ++i) {
        std::string arg = argv[i];
        bool takes_value = false;
        if (cpm::is_init_flag(arg.substr(0, arg.find('=')), takes_value)) {
            if (init_flags) init_flags->push_back(arg);
            if (takes_value && arg.find('=') == std::string::npos && i + 1 < argc) {
                ++i;
                if (init_flags) init_flags->push_back(argv[i]);
            }
            continue;
        }
        words.push_back(arg);
    }
    return words;
}

/// Whether an error message begins with the command it belongs to ("cpm history at: …", "cpm: …").
bool names_a_command(const char* message) { return std::strncmp(message, "cpm ", 4) == 0 || std::strncmp(message, "cpm:", 4) == 0; }

int dispatch(int argc, char** argv)
{
    std::vector<std::string> init_flags;
    const std::vector<std::string> args = command_words(argc, argv, &init_flags);
    const bool help = cpm::cli::wants_help(args);
    const auto all = all_commands();
    if (args.empty()) {
        std::fputs(overview(all, "").c_str(), stderr);
        return cpm::cli::kUsageExit;
    }
    if (args[0] == "--version" || args[0] == "version") {
        std::printf("cpm %s (Fast DDS %s)\n", CPM_VERSION, FASTRTPS_VERSION_STR);
        return 0;
    }
    if (args[0] == "help" || args[0] == "--help" || args[0] == "-h") {
        std::fputs(overview(all, "").c_str(), stdout);
        return 0;
    }
    bool group_known = false;
    for (const auto& c : all) {
        if (args[0] != c.group) continue;
        group_known = true;
        const bool verbless = *c.verb == 0;
        if (!verbless && (args.size() < 2 || args[1] != c.verb)) continue;
        if (help) {
            std::fputs(c.help, stdout);
            return 0;
        }
        cpm::init(argc, argv);  // cpm's own flags, checked before any waiting
        // The verb's arguments, and cpm's own flags after them: a verb that starts programs
        // (cpm vehicle sim) passes those on, so its children join the same domain.
        std::vector<std::string> rest(args.begin() + (verbless ? 1 : 2), args.end());
        rest.insert(rest.end(), init_flags.begin(), init_flags.end());
        try {
            return c.run(rest);
        } catch (const UsageError& e) {
            // A value's error from the shared parsers ("--time: 'x' is not a time") names the
            // command it was given to, as the commands' own messages do.
            if (names_a_command(e.what())) throw;
            const std::string command = verbless && !rest.empty() && rest[0].rfind("--", 0) != 0
                                            ? std::string("cpm ") + c.group + " " + rest[0]
                                            : std::string("cpm ") + c.group + (verbless ? "" : std::string(" ") + c.verb);
            throw UsageError(command + ": " + e.what());
        }
    }
    if (group_known) {
        if (help || args.size() < 2) {
            std::fputs(overview(all, args[0]).c_str(), help ? stdout : stderr);
            return help ? 0 : cpm::cli::kUsageExit;
        }
        throw UsageError("unknown command 'cpm " + args[0] + " " + args[1] + "' (see cpm " + args[0] + " --help)");
    }
    throw UsageError("unknown command '" + args[0] + "' (see cpm --help)");
}

void print_error(const char* message)
{
    // Messages that already name their command ("cpm history at: …") keep their own prefix.
    std::fprintf(stderr, names_a_command(message) ? "%s\n" : "cpm: %s\n", message);
}

}  // namespace

int main(int argc, char** argv)
{
    int status = 0;
    try {
        status = dispatch(argc, argv);
    } catch (const UsageError& e) {
        print_error(e.what());
        return cpm::cli::kUsageExit;
    } catch (const std::exception& e) {
        print_error(e.what());
        return 1;
    }
    // Output that never arrived (a full disk, a closed pipe) is a failure too.
    if (std::fflush(stdout) != 0 || std::ferror(stdout)) {
        std::fprintf(stderr, "cpm: cannot write the output: %s\n", std::strerror(errno));
        return 1;
    }
    return status;
}
