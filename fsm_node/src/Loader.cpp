#include <cpm/fsm/Loader.hpp>

#include "Elements.hpp"

#include <cpm/fsm/Uxf.hpp>
#include <cpm/Error.hpp>
#include <cpm/read_text_file.hpp>

#include <cstring>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <climits>
#include <sstream>
#include <filesystem>
#include <map>
#include <optional>
#include <set>

namespace cpm::fsm {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

const std::vector<std::string> kTopLevel{"root", "states", "transitions", "tick_period", "throttle_per_speed", "name"};

struct Context
{
    std::string source;              // file name for diagnostics
    fs::path base_dir;               // nested files are relative to it
    std::vector<std::string> stack;  // files being loaded (cycle check)
    Checker* check;                  // one for the machine and its nested files: each finding names its file
    void error(const std::string& path, const std::string& message) { check->error(source + ": " + path, message); }
    void warning(const std::string& path, const std::string& message) { check->warning(source + ": " + path, message); }
    /// `key` at `path` is none of `known`: named, with the one meant when it is close.
    std::string unknown(const std::string& what, const std::string& key, const std::vector<std::string>& known) const
    {
        std::string list;
        for (const auto& k : known) list += (list.empty() ? "" : ", ") + k;
        const auto meant = did_you_mean(key, known);
        return "unknown " + what + (meant ? " (did you mean \"" + *meant + "\"?)" : std::string()) +
               (list.empty() ? " (it takes none)" : " (known: " + list + ")");
    }
};

std::string kind_error(const std::string& kind)
{
    if (kind == "side") return "expected \"left\" or \"right\"";
    if (kind == "sensor") return "expected \"front\", \"left\" or \"right\"";
    if (kind == "direction") return "expected \"above\" or \"below\"";
    return "expected " + std::string(kind == "integer" ? "an integer" : kind == "bool" ? "true or false" : "a " + kind);
}

bool kind_ok(const std::string& kind, const json& v)
{
    if (kind == "number") return v.is_number();
    if (kind == "integer") return v.is_number_integer();
    if (kind == "bool") return v.is_boolean();
    if (kind == "side") return v.is_string() && (v == "left" || v == "right");
    if (kind == "sensor") return v.is_string() && (v == "front" || v == "left" || v == "right");
    if (kind == "direction") return v.is_string() && (v == "above" || v == "below");
    if (kind == "machine") return v.is_object();
    if (kind == "file") return v.is_string();
    return false;
}

json default_value(const ParameterInfo& p)
{
    if (p.kind == "number") return std::stod(p.fallback);
    if (p.kind == "integer") return std::stoi(p.fallback);
    if (p.kind == "bool") return p.fallback == "true";
    return p.fallback;
}

/// Checks an element's parameters against its type; fills in defaults. False on an error.
bool check_parameters(Context& ctx, const json& element, const std::string& path, const TypeInfo& info,
                      const std::set<std::string>& structural, detail::Params& params)
{
    bool ok = true;
    params = json::object();
    for (auto it = element.begin(); it != element.end(); ++it) {
        if (structural.count(it.key())) continue;
        auto p = std::find_if(info.parameters.begin(), info.parameters.end(), [&](auto& q) { return q.name == it.key(); });
        if (p == info.parameters.end()) {
            std::vector<std::string> known;
            for (auto& q : info.parameters) known.push_back(q.name);
            ctx.error(path + "." + it.key(), ctx.unknown("parameter of " + info.type, it.key(), known));
            ok = false;
        } else if (!kind_ok(p->kind, it.value())) {
            ctx.error(path + "." + it.key(), kind_error(p->kind) + ", got " + it.value().dump());
            ok = false;
        } else if ((p->kind == "number" || p->kind == "integer") &&
                   !(it.value().get<double>() >= p->min && it.value().get<double>() <= p->max)) {
            std::ostringstream range;
            range << "expected " << (p->kind == "integer" ? "an integer" : "a number") << " in " << p->min << ".."
                  << p->max << " (" << p->meaning << "), got " << it.value().dump();
            ctx.error(path + "." + it.key(), range.str());
            ok = false;
        } else {
            params[it.key()] = it.value();
        }
    }
    for (const auto& p : info.parameters) {
        // Given but wrong is said above, once.
        if (params.contains(p.name) || element.contains(p.name) || p.kind == "machine" || p.kind == "file") continue;
        if (p.fallback.empty()) {
            ctx.error(path, info.type + " needs parameter \"" + p.name + "\" (" + p.meaning + ")");
            ok = false;
        } else {
            params[p.name] = default_value(p);
        }
    }
    return ok;
}

std::optional<int> integer_member(Context& ctx, const json& e, const std::string& path, const char* name)
{
    if (!e.contains(name)) {
        ctx.error(path, std::string("missing \"") + name + "\"");
        return std::nullopt;
    }
    const json& v = e[name];
    // Ids are 32-bit: 4294967299 would silently become 3.
    if (!v.is_number_integer() || (v.is_number_unsigned() && v.get<uint64_t>() > uint64_t(INT32_MAX)) ||
        (!v.is_number_unsigned() && (v.get<int64_t>() < INT32_MIN || v.get<int64_t>() > INT32_MAX))) {
        ctx.error(path + "." + name, "expected an integer in " + std::to_string(INT32_MIN) + ".." + std::to_string(INT32_MAX) +
                                         ", got " + v.dump());
        return std::nullopt;
    }
    return v.get<int>();
}

std::unique_ptr<Machine> load_machine(Context& ctx, const json& j, const std::string& at);

/// The factory for the element's "type"; null (and an error naming the known types) if none.
template <class Factory>
const Factory* find_factory(Context& ctx, const std::vector<Factory>& factories, const json& e, const std::string& path,
                            const std::string& what)
{
    if (!e.contains("type") || !e["type"].is_string()) {
        ctx.error(path, "missing \"type\" (a " + what + " type name)");
        return nullptr;
    }
    const std::string type = e["type"];
    for (const auto& f : factories) {
        if (f.info.type == type) return &f;
    }
    std::vector<std::string> known;
    for (const auto& f : factories) known.push_back(f.info.type);
    ctx.error(path + ".type", ctx.unknown(what + " type \"" + type + "\"", type, known));
    return nullptr;
}

/// FSMState: the nested machine, inline or from a file.
std::unique_ptr<Machine> load_nested(Context& ctx, const json& e, const std::string& path)
{
    bool inline_machine = e.contains("machine"), from_file = e.contains("file");
    if (inline_machine == from_file) {
        ctx.error(path, "FSMState needs exactly one of \"machine\" (inline) or \"file\"");
        return nullptr;
    }
    if (inline_machine) return load_machine(ctx, e["machine"], path + ".machine");
    fs::path file = ctx.base_dir / e["file"].get<std::string>();
    std::error_code ec;
    auto canonical = fs::weakly_canonical(file, ec).string();
    if (!fs::exists(file)) {
        ctx.error(path + ".file", "nested machine file " + file.string() + " does not exist");
        return nullptr;
    }
    if (std::find(ctx.stack.begin(), ctx.stack.end(), canonical) != ctx.stack.end()) {
        ctx.error(path + ".file", "nested machine file " + file.string() + " includes itself (cycle)");
        return nullptr;
    }
    json nested;
    try {
        nested = json::parse(cpm::read_text_file(file.string(), "nested machine file"));
    } catch (const json::exception& err) {
        ctx.error(path + ".file", file.string() + " is not valid JSON (" + err.what() + ")");
        return nullptr;
    } catch (const cpm::Error& err) {
        ctx.error(path + ".file", err.what());
        return nullptr;
    }
    Context inner{file.string(), file.parent_path(), ctx.stack, ctx.check};
    inner.stack.push_back(canonical);
    return load_machine(inner, nested, "$");
}

std::unique_ptr<Machine> load_machine(Context& ctx, const json& j, const std::string& at)
{
    const size_t errors_before = ctx.check->errors().size();
    if (!j.is_object()) {
        ctx.error(at, "expected an object with \"root\", \"states\" and \"transitions\"");
        return nullptr;
    }
    for (auto it = j.begin(); it != j.end(); ++it) {
        if (std::find(kTopLevel.begin(), kTopLevel.end(), it.key()) == kTopLevel.end()) ctx.error(at + "." + it.key(), ctx.unknown("member", it.key(), kTopLevel));
    }
    detail::Settings settings;
    if (j.contains("tick_period")) {
        if (!j["tick_period"].is_number() || j["tick_period"].get<double>() <= 0) ctx.error(at + ".tick_period", "expected a number > 0 (s)");
        else settings.tick_period = j["tick_period"].get<double>();
    }
    if (j.contains("throttle_per_speed")) {
        if (!j["throttle_per_speed"].is_number() || !(j["throttle_per_speed"].get<double>() > 0 && j["throttle_per_speed"].get<double>() <= 10))
            ctx.error(at + ".throttle_per_speed", "expected a number in 0..10 (throttle per m/s), got " + j["throttle_per_speed"].dump());
        else settings.throttle_per_speed = j["throttle_per_speed"].get<double>();
    }
    auto root = integer_member(ctx, j, at, "root");

    // States.
    std::vector<std::unique_ptr<State>> states;
    std::map<int, const TypeInfo*> state_types;
    std::map<int, bool> final_states;
    std::set<int> untyped_ids;
    auto exists = [&](int id) { return state_types.count(id) || untyped_ids.count(id); };
    if (!j.contains("states") || !j["states"].is_array()) {
        ctx.error(at + ".states", "expected an array of states");
    } else if (j["states"].empty()) {
        ctx.error(at + ".states", "the machine has no states (an empty drawing?)");
    } else {
        for (size_t k = 0; k < j["states"].size(); ++k) {
            const json& e = j["states"][k];
            std::string path = at + ".states[" + std::to_string(k) + "]";
            if (!e.is_object()) {
                ctx.error(path, "expected an object");
                continue;
            }
            auto id = integer_member(ctx, e, path, "id");
            const auto* f = find_factory(ctx, detail::state_factories(), e, path, "state");
            if (!f) {
                if (id) untyped_ids.insert(*id);  // it exists; its type was already reported
                continue;
            }
            const std::string type = f->info.type;
            if (e.contains("final") && !e["final"].is_boolean()) ctx.error(path + ".final", "expected true or false");
            detail::Params params;
            bool params_ok = check_parameters(ctx, e, path, f->info, {"id", "type", "final"}, params);
            if (!id) continue;
            if (state_types.count(*id)) {
                ctx.error(path + ".id", "duplicate state id " + std::to_string(*id));
                continue;
            }
            state_types[*id] = &f->info;
            final_states[*id] = e.contains("final") && e["final"].is_boolean() && e["final"].get<bool>();
            std::unique_ptr<State> state;
            if (type == "FSMState") {
                auto nested = load_nested(ctx, e, path);
                if (nested) {
                    bool has_final = false;
                    for (auto& s : nested->states()) has_final = has_final || s->is_final();
                    if (!has_final) ctx.error(path, "the nested machine has no state marked \"final\": true, so this FSMState can never finish");
                    state = detail::make_nested_state(*id, std::move(nested));
                }
            } else if (params_ok) {
                state = f->make(*id, params, settings);
            }
            if (state) {
                state->set_final(final_states[*id]);
                states.push_back(std::move(state));
            }
        }
    }
    if (root && !state_types.empty() && !exists(*root)) ctx.error(at + ".root", "state " + std::to_string(*root) + " does not exist");

    // Transitions.
    std::vector<std::unique_ptr<Transition>> transitions;
    std::set<int> transition_ids;
    std::multimap<int, int> edges;
    if (j.contains("transitions") && !j["transitions"].is_array()) ctx.error(at + ".transitions", "expected an array of transitions");
    const json empty = json::array();
    const json& list = j.contains("transitions") && j["transitions"].is_array() ? j["transitions"] : empty;
    for (size_t k = 0; k < list.size(); ++k) {
        const json& e = list[k];
        std::string path = at + ".transitions[" + std::to_string(k) + "]";
        if (!e.is_object()) {
            ctx.error(path, "expected an object");
            continue;
        }
        auto id = integer_member(ctx, e, path, "id");
        auto from = integer_member(ctx, e, path, "from");
        auto to = integer_member(ctx, e, path, "to");
        const auto* f = find_factory(ctx, detail::transition_factories(), e, path, "transition");
        if (!f) continue;
        const std::string type = f->info.type;
        detail::Params params;
        bool params_ok = check_parameters(ctx, e, path, f->info, {"id", "type", "from", "to"}, params);
        if (id && !transition_ids.insert(*id).second) ctx.error(path + ".id", "duplicate transition id " + std::to_string(*id));
        if (from && !exists(*from)) ctx.error(path + ".from", "state " + std::to_string(*from) + " does not exist");
        if (to && !exists(*to)) ctx.error(path + ".to", "state " + std::to_string(*to) + " does not exist");
        if (!id || !from || !to || !state_types.count(*from) || !state_types.count(*to)) continue;
        if (type == "Finished" && !state_types[*from]->finishable) {
            ctx.error(path, "Finished from state " + std::to_string(*from) + " (" + state_types[*from]->type + "), which never finishes");
        }
        if (type == "ArucoGateFound" && !state_types[*to]->targetable) {
            ctx.error(path, "ArucoGateFound into state " + std::to_string(*to) + " (" + state_types[*to]->type + "), which cannot take a target");
        }
        edges.emplace(*from, *to);
        if (params_ok) transitions.push_back(f->make(*id, *from, *to, params));
    }

    // Warnings: unreachable states, states with no way out.
    if (root && state_types.count(*root)) {
        std::set<int> seen{*root};
        std::vector<int> todo{*root};
        while (!todo.empty()) {
            int s = todo.back();
            todo.pop_back();
            auto range = edges.equal_range(s);
            for (auto it = range.first; it != range.second; ++it) {
                if (seen.insert(it->second).second) todo.push_back(it->second);
            }
        }
        for (auto& [id, info] : state_types) {
            if (!seen.count(id)) ctx.warning(at + ".states", "state " + std::to_string(id) + " (" + info->type + ") cannot be reached from the root");
            bool way_out = edges.count(id) > 0;
            if (!way_out && !final_states[id] && info->type != "Stop" && info->type != "Idle") {
                ctx.warning(at + ".states", "state " + std::to_string(id) + " (" + info->type + ") has no way out and is not marked final");
            }
        }
    }
    if (ctx.check->errors().size() != errors_before || !root) return nullptr;
    return std::make_unique<Machine>(std::move(states), std::move(transitions), *root);
}

}  // namespace

namespace {

/// Checks a machine's JSON text; `stack` holds the files being loaded (for the cycle check).
LoadResult check_text(const std::string& text, const std::string& source, const fs::path& base_dir,
                      std::vector<std::string> stack)
{
    LoadResult result;
    json j;
    try {
        j = json::parse(text);
    } catch (const json::exception& e) {
        result.errors.push_back({source, std::string("not valid JSON (") + e.what() + ")"});
        return result;
    }
    Checker check("");
    Context ctx{source, base_dir, std::move(stack), &check};
    auto machine = load_machine(ctx, j, "$");
    result.errors = check.errors();
    result.warnings = check.warnings();
    if (result.errors.empty()) result.machine = std::move(machine);
    result.json = text;
    return result;
}

/// A .uxf drawing: converted, then checked like JSON; diagnostics name the drawing's elements.
LoadResult load_uxf(const std::string& path, const std::string& text, const fs::path& dir, const std::string& canonical)
{
    auto conversion = convert_uxf(text, path);
    if (!conversion.errors.empty()) {
        LoadResult result;
        result.errors = conversion.errors;
        return result;
    }
    LoadResult result = check_text(conversion.json, path, dir, {canonical});
    auto name_element = [&](Diagnostic& d) {
        for (auto [list, origins] : {std::pair{"$.states[", &conversion.state_origin},
                                     std::pair{"$.transitions[", &conversion.transition_origin}}) {
            auto at = d.where.find(list);
            if (at == std::string::npos) continue;
            size_t k = std::strtoul(d.where.c_str() + at + std::strlen(list), nullptr, 10);
            if (k < origins->size()) d.where += " = " + (*origins)[k];
        }
    };
    for (auto& d : result.errors) name_element(d);
    for (auto& d : result.warnings) name_element(d);
    return result;
}

}  // namespace

LoadResult load_json(const std::string& json_text, const std::string& source, const std::string& base_dir)
{
    return check_text(json_text, source, base_dir, {});
}

LoadResult load_file(const std::string& path)
{
    std::string text;
    try {
        text = cpm::read_text_file(path, "state machine file");
    } catch (const cpm::Error& e) {
        LoadResult result;
        const std::string message = e.what();
        result.errors.push_back({path, message.substr(path.size() + 2)});  // the path is the diagnostic's place
        return result;
    }
    std::error_code ec;
    const fs::path dir = fs::path(path).parent_path().empty() ? fs::path(".") : fs::path(path).parent_path();
    const std::string canonical = fs::weakly_canonical(path, ec).string();
    if (fs::path(path).extension() == ".uxf") return load_uxf(path, text, dir, canonical);
    return check_text(text, path, dir, {canonical});
}

const std::vector<TypeInfo>& known_types()
{
    static const std::vector<TypeInfo> types = [] {
        std::vector<TypeInfo> all;
        for (auto& f : detail::state_factories()) all.push_back(f.info);
        for (auto& f : detail::transition_factories()) all.push_back(f.info);
        return all;
    }();
    return types;
}

}  // namespace cpm::fsm
