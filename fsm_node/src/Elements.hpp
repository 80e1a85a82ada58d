#pragma once
// The state and transition types and their parameter tables (used by the loader).
#include <cpm/fsm/Loader.hpp>
#include <cpm/fsm/Machine.hpp>

#include <nlohmann/json.hpp>

#include <functional>
#include <memory>

namespace cpm::fsm::detail {

/// Checked parameters of one element (every parameter present, defaults filled in).
using Params = nlohmann::json;

/// Machine-wide settings the elements need.
struct Settings
{
    double tick_period = 0.0125;       ///< PID_S of the original (s); PID_INVS = 1 / tick_period
    double throttle_per_speed = 1 / 3.0;  ///< throttle for 1 m/s (the simulated car: 3 m/s at full throttle)
};

struct StateFactory
{
    TypeInfo info;
    std::function<std::unique_ptr<State>(int id, const Params&, const Settings&)> make;
};
struct TransitionFactory
{
    TypeInfo info;
    std::function<std::unique_ptr<Transition>(int id, int from, int to, const Params&)> make;
};

const std::vector<StateFactory>& state_factories();
const std::vector<TransitionFactory>& transition_factories();

/// A nested machine for FSMState (built by the loader, which also checks it).
std::unique_ptr<State> make_nested_state(int id, std::unique_ptr<Machine> nested);

}  // namespace cpm::fsm::detail
