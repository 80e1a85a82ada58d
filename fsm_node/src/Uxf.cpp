#include <cpm/fsm/Uxf.hpp>

#include <nlohmann/json.hpp>
#include <tinyxml2.h>

#include <cmath>
#include <sstream>

namespace cpm::fsm {
namespace {

using nlohmann::json;

struct Box
{
    double x = 0, y = 0, w = 0, h = 0;
    bool touches(double px, double py, double slack) const
    {
        return px >= x - slack && px <= x + w + slack && py >= y - slack && py <= y + h + slack;
    }
};

std::string trim(std::string s)
{
    const char* ws = " \t\r\n";
    s.erase(0, s.find_first_not_of(ws));
    auto end = s.find_last_not_of(ws);
    return end == std::string::npos ? "" : s.substr(0, end + 1);
}

/// `"key": value`, `key: value` or `key=value` per line (a trailing comma is fine) → members.
bool parse_members(const std::vector<std::string>& lines, json& out, std::string& problem)
{
    out = json::object();
    for (auto line : lines) {
        line = trim(line);
        if (line.empty()) continue;
        if (line.back() == ',') line.pop_back();
        // Several members on one line, separated by commas, are read as one JSON object.
        try {
            json members = json::parse("{" + line + "}");
            for (auto it = members.begin(); it != members.end(); ++it) out[it.key()] = it.value();
            continue;
        } catch (const json::exception&) {
        }
        auto sep = line.find_first_of(":=");
        if (sep == std::string::npos) {
            problem = "cannot read the parameter line '" + line + "' (expected key: value)";
            return false;
        }
        std::string key = trim(line.substr(0, sep)), value = trim(line.substr(sep + 1));
        if (key.size() >= 2 && key.front() == '"' && key.back() == '"') key = key.substr(1, key.size() - 2);
        try {
            out[key] = json::parse(value);
        } catch (const json::exception&) {
            out[key] = value;  // a bare word: a string
        }
    }
    return true;
}

std::vector<std::string> lines_of(const std::string& text)
{
    std::vector<std::string> lines;
    std::istringstream in(text);
    for (std::string l; std::getline(in, l);) lines.push_back(l);
    return lines;
}

double number_child(const tinyxml2::XMLElement* parent, const char* name)
{
    const auto* e = parent ? parent->FirstChildElement(name) : nullptr;
    return e && e->GetText() ? std::atof(e->GetText()) : 0.0;
}

}  // namespace

UxfConversion convert_uxf(const std::string& xml_text, const std::string& source)
{
    UxfConversion result;
    auto error = [&](const std::string& where, const std::string& message) {
        result.errors.push_back({source + (where.empty() ? "" : ": " + where), message});
    };
    tinyxml2::XMLDocument doc;
    if (doc.Parse(xml_text.c_str(), xml_text.size()) != tinyxml2::XML_SUCCESS) {
        error("", std::string("not a readable UMLet file (") + doc.ErrorStr() + ")");
        return result;
    }
    const auto* diagram = doc.FirstChildElement("diagram");
    if (!diagram) {
        error("", "no <diagram> element: not a UMLet file");
        return result;
    }
    json machine{{"states", json::array()}, {"transitions", json::array()}};
    std::vector<std::pair<int, Box>> boxes;  // state id, its box
    std::optional<int> root;
    struct PendingRelation
    {
        json members;
        std::string origin;
        double x1, y1, x2, y2;
    };
    std::vector<PendingRelation> relations;

    int index = 0;
    for (const auto* e = diagram->FirstChildElement("element"); e; e = e->NextSiblingElement("element"), ++index) {
        const auto* id_el = e->FirstChildElement("id");
        const std::string kind = id_el && id_el->GetText() ? id_el->GetText() : "";
        const auto* coords = e->FirstChildElement("coordinates");
        Box box{number_child(coords, "x"), number_child(coords, "y"), number_child(coords, "w"), number_child(coords, "h")};
        const auto* panel = e->FirstChildElement("panel_attributes");
        const std::string text = panel && panel->GetText() ? panel->GetText() : "";
        std::ostringstream origin;
        origin << "element " << index << " (" << kind << " at " << box.x << "," << box.y << ")";
        auto lines = lines_of(text);

        if (kind == "UMLState") {
            std::vector<size_t> separators;
            for (size_t i = 0; i < lines.size(); ++i) {
                if (trim(lines[i]) == "--") separators.push_back(i);
            }
            if (separators.size() < 2) {
                error(origin.str(), "a state's parameters must stand between two '--' lines");
                continue;
            }
            json members;
            std::string problem;
            if (!parse_members({lines.begin() + long(separators[0]) + 1, lines.begin() + long(separators[1])}, members, problem)) {
                error(origin.str(), problem);
                continue;
            }
            if (members.contains("root")) {
                if (members["root"] == true && members.contains("id") && members["id"].is_number_integer()) root = members["id"].get<int>();
                members.erase("root");
            }
            if (members.contains("id") && members["id"].is_number_integer()) boxes.emplace_back(members["id"].get<int>(), box);
            machine["states"].push_back(members);
            result.state_origin.push_back(origin.str());
        } else if (kind == "UMLNote" && !lines.empty() && trim(lines[0]) == "machine") {
            json members;
            std::string problem;
            if (!parse_members({lines.begin() + 1, lines.end()}, members, problem)) {
                error(origin.str(), problem);
                continue;
            }
            for (auto it = members.begin(); it != members.end(); ++it) {
                if (it.key() == "states" || it.key() == "transitions" || it.key() == "root") {
                    error(origin.str(), "\"" + it.key() + "\" comes from the drawing (state boxes, arrows, \"root\": true), not from the machine note");
                } else {
                    machine[it.key()] = it.value();
                }
            }
        } else if (kind == "Relation") {
            size_t arrow = lines.size();
            for (size_t i = 0; i < lines.size(); ++i) {
                if (trim(lines[i]).rfind("lt=", 0) == 0) arrow = i;
            }
            if (arrow == lines.size() || trim(lines[arrow]) != "lt=->") continue;  // not a transition arrow
            json members;
            std::string problem;
            if (!parse_members({lines.begin() + long(arrow) + 1, lines.end()}, members, problem)) {
                error(origin.str(), problem);
                continue;
            }
            const auto* extra = e->FirstChildElement("additional_attributes");
            std::vector<double> points;
            std::stringstream in(extra && extra->GetText() ? extra->GetText() : "");
            for (std::string v; std::getline(in, v, ';');) {
                if (!trim(v).empty()) points.push_back(std::atof(v.c_str()));
            }
            if (points.size() < 4) points = {0, 0, 0, 0};
            relations.push_back({members, origin.str(), box.x + points[0], box.y + points[1],
                                 box.x + points[points.size() - 2], box.y + points[points.size() - 1]});
        }
    }
    // Transitions: the end points say which boxes they join, unless from/to are given.
    for (auto& r : relations) {
        auto touched = [&](double px, double py) -> std::optional<int> {
            for (auto& [id, b] : boxes) {
                if (b.touches(px, py, 5)) return id;
            }
            return std::nullopt;
        };
        if (!r.members.contains("from")) {
            if (auto id = touched(r.x1, r.y1)) r.members["from"] = *id;
            else error(r.origin, "the arrow's start touches no state box and the transition gives no \"from\"");
        }
        if (!r.members.contains("to")) {
            if (auto id = touched(r.x2, r.y2)) r.members["to"] = *id;
            else error(r.origin, "the arrow's end touches no state box and the transition gives no \"to\"");
        }
        machine["transitions"].push_back(r.members);
        result.transition_origin.push_back(r.origin);
    }
    machine["root"] = root.value_or(0);
    // Text that is not UTF-8 (a drawing saved in another encoding) keeps its place as U+FFFD.
    if (result.errors.empty()) result.json = machine.dump(2, ' ', false, json::error_handler_t::replace);
    return result;
}

}  // namespace cpm::fsm
