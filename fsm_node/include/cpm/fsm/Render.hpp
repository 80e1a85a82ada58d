#pragma once
#include <cpm/fsm/Loader.hpp>

#include <string>
#include <vector>

namespace cpm::fsm {

/// A checked machine as a Graphviz graph: states as boxes labelled with id, type and key
/// parameters (the root drawn bold, final states double-framed), transitions as arrows labelled
/// with their id, type and condition.
struct DotResult
{
    std::string dot;
    std::vector<Diagnostic> errors;
};

/// Loads and checks FILE (.json or .uxf) and writes the graph; errors as load_file gives them.
DotResult machine_to_dot(const std::string& path);

}  // namespace cpm::fsm
