#pragma once
#include <cpm/Diagnostics.hpp>
#include <cpm/fsm/Machine.hpp>

#include <memory>
#include <string>
#include <vector>

namespace cpm::fsm {

/// One finding of the check: where (file and JSON path, e.g. `car.json: $.states[2].p`) and what.
using Diagnostic = cpm::Diagnostic;

/// The outcome of loading: every error and warning at once; a machine only when no error.
struct LoadResult
{
    std::unique_ptr<Machine> machine;
    std::vector<Diagnostic> errors;
    std::vector<Diagnostic> warnings;
    std::string json;  ///< the machine as JSON text: the file itself, or the drawing converted
    bool ok() const { return errors.empty(); }
};

/// Loads and checks a machine from a JSON file (nested FSMState files relative to it).
LoadResult load_file(const std::string& path);
/// The same from JSON text; `source` names it in diagnostics, `base_dir` resolves nested files.
LoadResult load_json(const std::string& json_text, const std::string& source, const std::string& base_dir = ".");

/// A parameter of a state or transition type, for documentation and checking.
struct ParameterInfo
{
    std::string name;
    std::string kind;       ///< number, integer, bool, side, sensor, direction, machine
    std::string fallback;   ///< the default as text, empty when required
    std::string meaning;
    double min = -1e300;    ///< number and integer kinds: the range a value must lie in
    double max = 1e300;
};

/// Every state and transition type the loader knows, with its parameters.
struct TypeInfo
{
    std::string type;
    bool is_state = true;
    bool finishable = false;
    bool targetable = false;
    std::vector<ParameterInfo> parameters;
};
const std::vector<TypeInfo>& known_types();

}  // namespace cpm::fsm
