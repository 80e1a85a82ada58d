#include <cpm/fsm/Machine.hpp>

#include <stdexcept>

namespace cpm::fsm {

Machine::Machine(std::vector<std::unique_ptr<State>> states, std::vector<std::unique_ptr<Transition>> transitions,
                 int root)
    : states_(std::move(states)), transitions_(std::move(transitions)), root_(root)
{
    active_ = state_by_id(root);
    if (!active_) throw cpm::Error("fsm: the root state " + std::to_string(root) + " does not exist");
}

State* Machine::state_by_id(int id) const
{
    for (const auto& s : states_) {
        if (s->id() == id) return s.get();
    }
    return nullptr;
}

void Machine::enter(State* state, const Inputs& in)
{
    active_ = state;
    entered_t_ = in.t;
    active_->on_enter(in);
    for (const auto& t : transitions_) {
        if (t->from() == active_->id()) t->reset();
    }
}

void Machine::start(const Inputs& in)
{
    started_ = true;
    enter(state_by_id(root_), in);
}

Output Machine::tick(const Inputs& in, double dt)
{
    if (!started_) start(in);
    Output out = active_->tick(in, dt);
    for (const auto& t : transitions_) {
        if (t->from() != active_->id() || !t->fires(in, *active_)) continue;
        State* next = state_by_id(t->to());
        active_->on_exit();
        last_transition_ = t->id();
        enter(next, in);
        if (auto target = t->target(); target && next->can_take_target()) next->set_target(*target);
        break;
    }
    return out;
}

bool uses_markers(const Machine& m)
{
    for (const auto& st : m.states()) {
        if (st->type().find("Aruco") != std::string::npos) return true;
    }
    for (const auto& t : m.transitions()) {
        if (t->type().find("Aruco") != std::string::npos) return true;
    }
    return false;
}

}  // namespace cpm::fsm
