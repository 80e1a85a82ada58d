#pragma once
#include <string>
#include <vector>

namespace cpm::tools {

extern const char* kHistoryHelp;
extern const char* kDumpHelp;
/// `cpm history VERB ...`: list, at, older, younger, range, latest, wait, successor, search, snapshot.
int history_command(const std::string& verb, const std::vector<std::string>& args);
/// `cpm dump`: one table of every object the history service holds.
int dump_command(const std::vector<std::string>& args);

}  // namespace cpm::tools
