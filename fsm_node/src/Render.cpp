#include <cpm/fsm/Render.hpp>

#include <nlohmann/json.hpp>

#include <sstream>

namespace cpm::fsm {
namespace {

using nlohmann::json;

std::string escape(const std::string& s)
{
    std::string out;
    for (char c : s) {
        if (c == '\n') {
            out += "\\n";  // a line break in a Graphviz label
            continue;
        }
        if (c == '"' || c == '\\') out += '\\';
        out += c;
    }
    return out;
}

/// "key value" pairs of the members that are not structure.
std::string parameters(const json& element, std::initializer_list<const char*> skip, const char* separator)
{
    std::string out;
    for (auto it = element.begin(); it != element.end(); ++it) {
        bool skipped = false;
        for (const char* k : skip) skipped = skipped || it.key() == k;
        if (skipped) continue;
        std::string value = it.value().is_string() ? it.value().get<std::string>() : it.value().dump();
        out += (out.empty() ? "" : separator) + it.key() + " " + value;
    }
    return out;
}

}  // namespace

DotResult machine_to_dot(const std::string& path)
{
    DotResult result;
    auto checked = load_file(path);
    if (!checked.ok()) {
        result.errors = checked.errors;
        return result;
    }
    const json j = json::parse(checked.json);
    std::ostringstream dot;
    dot << "digraph fsm {\n  rankdir=LR;\n  node [shape=box, style=rounded, fontname=\"Helvetica\"];\n"
        << "  edge [fontname=\"Helvetica\", fontsize=10];\n";
    if (j.contains("name")) dot << "  label=\"" << escape(j["name"].get<std::string>()) << "\";\n";
    const int root = j["root"].get<int>();
    for (const auto& s : j["states"]) {
        const int id = s["id"].get<int>();
        std::string label = std::to_string(id) + ": " + s["type"].get<std::string>();
        if (id == root) label += " (root)";
        std::string params = parameters(s, {"id", "type", "final", "root"}, "\n");
        if (!params.empty()) label += "\n" + params;
        dot << "  \"s" << id << "\" [label=\"" << escape(label) << "\"";
        if (id == root) dot << ", style=\"rounded,bold\"";
        if (s.value("final", false)) dot << ", peripheries=2";
        dot << "];\n";
    }
    for (const auto& t : j.value("transitions", json::array())) {
        std::string label = std::to_string(t["id"].get<int>()) + ": " + t["type"].get<std::string>();
        std::string params = parameters(t, {"id", "type", "from", "to"}, ", ");
        if (!params.empty()) label += "\n" + params;
        dot << "  \"s" << t["from"].get<int>() << "\" -> \"s" << t["to"].get<int>() << "\" [label=\"" << escape(label) << "\"];\n";
    }
    dot << "}\n";
    result.dot = dot.str();
    return result;
}

}  // namespace cpm::fsm
