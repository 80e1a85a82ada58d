#pragma once
#include <cpm/fsm/Loader.hpp>

#include <string>
#include <vector>

namespace cpm::fsm {

/// A UMLet drawing turned into the machine's JSON text, and where each state and transition of
/// it came from in the drawing (for diagnostics).
struct UxfConversion
{
    std::string json;                        ///< empty when there were errors
    std::vector<std::string> state_origin;   ///< per states[k]: "element 3 (UMLState at 120,80)"
    std::vector<std::string> transition_origin;
    std::vector<Diagnostic> errors;
};

/// Reads a UMLet `.uxf` drawing: a state is a `UMLState` element whose parameters stand between
/// the two `--` lines of its panel attributes (`"id": 0`, `"type": "FollowWall"`, one member per
/// line; `"root": true` marks the root, else state 0 is the root); a transition is a `Relation`
/// with `lt=->` whose parameters follow that line. A transition without `from`/`to` takes them
/// from the drawing: the state boxes its two end points touch. A `UMLNote` whose first line is
/// `machine` holds the machine's own members (`"tick_period": 0.02`, `"name": …`).
UxfConversion convert_uxf(const std::string& xml_text, const std::string& source);

}  // namespace cpm::fsm
