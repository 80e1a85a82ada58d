#pragma once
// The `cpm` command's verb groups: each file (lab.cpp, topic.cpp, fsm.cpp, …) parses its verbs'
// flags, calls the libraries and prints; nothing here is meant for programs linking cpm.
#include <cpm/CommandLine.hpp>
#include <cpm/Participant.hpp>

#include <string>
#include <vector>

namespace cpm::tools {

// The command-line vocabulary every verb file uses.
using cpm::cli::FlagSpec;
using cpm::cli::ParsedArgs;
using cpm::cli::UsageError;
using cpm::cli::parse_args;
using cpm::cli::parse_flags;
using cpm::cli::parse_duration;
using cpm::cli::split_list;

/// One verb of one group: `cpm GROUP VERB [args]` (`verb` empty: the group takes no verb).
struct Command
{
    const char* group;
    const char* verb;
    const char* summary;  ///< one line for `cpm --help` and `cpm GROUP --help`
    const char* help;     ///< the verb's --help
    int (*run)(const std::vector<std::string>& args);  ///< the arguments after the command words
};

std::vector<Command> lab_commands();
std::vector<Command> topic_commands();
std::vector<Command> param_commands();
std::vector<Command> fsm_commands();
std::vector<Command> vehicle_commands();
std::vector<Command> history_commands();
std::vector<Command> aruco_commands();
std::vector<Command> routing_commands();
std::vector<Command> record_commands();
std::vector<Command> monitor_commands();
std::vector<Command> security_commands();
std::vector<Command> host_commands();

/// The participant options of cpm::init, named `name` unless --node_id named the process: a
/// command whose role others tell by its name (cpm_play, cpm_monitor).
cpm::ParticipantOptions named_participant(const std::string& name);

/// The single positional argument a command takes (`what` names it in the error).
std::string only_positional(const cpm::cli::ParsedArgs& parsed, const std::string& command, const std::string& what);

}  // namespace cpm::tools
