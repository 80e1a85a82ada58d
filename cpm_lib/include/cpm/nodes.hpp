#pragma once
// Which process uses which topic, in one table beside the topics' own (topics.hpp): each of
// cpm's programs (a node kind), the topics it writes and reads, and the id of its timer on the
// lab clock. A lab run's plan, its security grants (`cpm security add-node --kind`, a secured
// run's per-process nodes), the player's list of topics it never replays, and the tests that
// check each program's readers and writers all read it here, so a new topic is one line.
//
//   const auto& fsm = cpm::nodes::find("fsm_node");  // publish: vehicleCommandDirect, fsmStatus, ...
//   fsm.timer(3);                                    // "fsm_node_3"
//
// Topic entries may be patterns (fnmatch: `*`, `?`): `historyReply*`, or `*` for a node that may
// read anything (the history, the monitor).
#include <string>
#include <string_view>
#include <vector>

namespace cpm::nodes {

struct NodeSpec
{
    std::string name;                    ///< the program, or for a part every program has, that part
    std::vector<std::string> publish;    ///< topics it writes
    std::vector<std::string> subscribe;  ///< topics it reads
    std::string (*timer)(int vehicle_id) = nullptr;  ///< its timer's node id on the lab clock; null: none
    /// What it writes steers the lab (its clock, parameters, the history's answers), it is no
    /// record of what happened: a recording's player never publishes it again.
    bool steers_the_lab = false;
    const char* about = "";
};

/// Every row: first the parts every cpm program has (`logging`, `lab_timer`, `parameter_client`,
/// `history_client`), then the programs.
const std::vector<NodeSpec>& all();
/// The row of a name; throws cpm::Error naming the known ones when there is none.
const NodeSpec& find(std::string_view name);
/// The names of the programs' rows (not the parts), for `--kind` and help texts.
std::vector<std::string> kinds();

/// What every program writes and reads by itself (its log, its timer's readiness and the lab's
/// start, its parameters): granted to every node of a secured lab.
std::vector<std::string> builtin_publish();
std::vector<std::string> builtin_subscribe();

/// The topics (and patterns) whose writers steer the lab: a player never replays them.
std::vector<std::string> control_topics();
/// Whether `topic` matches one of `patterns` (fnmatch).
bool matches(const std::string& topic, const std::vector<std::string>& patterns);

}  // namespace cpm::nodes
