#include <cpm_test/McapCheck.hpp>

#include <cpm_test/Process.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>
#include <set>
#include <sstream>
#include <vector>

namespace cpm_test {

namespace {

std::vector<nlohmann::json> json_lines(const std::string& text)
{
    std::vector<nlohmann::json> out;
    std::istringstream in(text);
    for (std::string line; std::getline(in, line);) {
        if (!line.empty()) out.push_back(nlohmann::json::parse(line));
    }
    return out;
}

/// Where `ours` (cpm's decoding) and `theirs` (Foxglove's) differ, by field path; "" if nowhere.
/// 64-bit integers come from Node as text.
std::string differs(const nlohmann::json& ours, const nlohmann::json& theirs, const std::string& path)
{
    if (ours.is_object() && theirs.is_object()) {
        std::string out;
        for (const auto& [k, v] : theirs.items()) {
            out += ours.contains(k) ? differs(ours[k], v, path + "." + k) : path + "." + k + ": missing in cpm's answer\n";
        }
        for (const auto& [k, v] : ours.items()) {
            if (!theirs.contains(k)) out += path + "." + k + ": missing in the reference reader's\n";
        }
        return out;
    }
    if (ours.is_array() && theirs.is_array()) {
        if (ours.size() != theirs.size()) return path + ": " + std::to_string(ours.size()) + " elements, the reference reader " + std::to_string(theirs.size()) + "\n";
        std::string out;
        for (size_t i = 0; i < ours.size(); ++i) out += differs(ours[i], theirs[i], path + "[" + std::to_string(i) + "]");
        return out;
    }
    const bool same = (ours.is_number_integer() && theirs.is_string())  ? ours.dump() == theirs.get<std::string>()
                      : (ours.is_number() && theirs.is_number())        ? ours.get<double>() == theirs.get<double>()
                      : (ours.is_string() && ours.get<std::string>() == "nan" && theirs.is_null()) ? true  // JSON has no NaN
                                                                                         : ours == theirs;
    return same ? "" : path + ": cpm " + ours.dump() + ", the reference reader " + theirs.dump() + "\n";
}

}  // namespace

std::vector<nlohmann::json> mcap_reference_read(const std::string& file, std::string& error)
{
    const std::string modules = std::string(CPM_MCAP_CHECK_DIR) + "/node_modules";
    if (!std::filesystem::exists(modules + "/@mcap/core")) {
        error = "the MCAP reference reader is not installed in " + modules + " (./lab test installs it with npm ci)";
        return {};
    }
    Process node({"/usr/bin/env", "NODE_PATH=" + modules, "node", CPM_MCAP_CHECK_SCRIPT, file});
    if (node.wait(std::chrono::seconds(120)) != 0) {
        error = "the reference reader refuses " + file + ": " + node.errors();
        return {};
    }
    std::vector<nlohmann::json> lines = json_lines(node.output());
    if (lines.empty()) error = "the reference reader printed nothing for " + file;
    return lines;
}

std::string mcap_differences(const std::string& file, long expected_messages)
{
    std::string error;
    std::vector<nlohmann::json> theirs = mcap_reference_read(file, error);
    if (!error.empty()) return error;
    const nlohmann::json totals = theirs.back();
    theirs.pop_back();
    std::string out;
    // Channels cpm derives for viewers (the cars' poses as Foxglove transforms) are no samples
    // of the run: each must decode, none is compared.
    std::vector<nlohmann::json> derived;
    theirs.erase(std::remove_if(theirs.begin(), theirs.end(),
                                [&](const nlohmann::json& m) {
                                    if (!m.value("derived", false)) return false;
                                    derived.push_back(m);
                                    return true;
                                }),
                 theirs.end());
    for (const auto& m : derived) {
        if (m["data"].is_null()) out += "a derived message on " + m["topic"].get<std::string>() + " does not decode\n";
    }
    if (expected_messages >= 0 && long(theirs.size()) != expected_messages) {
        out += "the reference reader read " + std::to_string(theirs.size()) + " messages of the run, " + std::to_string(expected_messages) +
               " expected\n";
    }
    std::multimap<std::pair<std::string, std::string>, const nlohmann::json*> by_time;  // (topic, log_time)
    for (const auto& m : theirs) by_time.emplace(std::make_pair(m["topic"].get<std::string>(), m["log_time"].get<std::string>()), &m);

    Process list({built_program("cpm"), "history", "--file", file, "list", "--json"});
    if (list.wait(std::chrono::seconds(60)) != 0) return out + "cpm history --file " + file + " list: " + list.errors();
    size_t ours = 0;
    std::set<std::pair<std::string, std::string>> asked;  // a range by name answers every object of that name
    for (const auto& object : json_lines(list.output())) {
        if (object["kind"] != "instance" || object["samples_total"] == 0) continue;
        if (!asked.insert({object["topic"].get<std::string>(), object["key"].get<std::string>()}).second) continue;
        std::vector<std::string> argv{built_program("cpm"), "history", "--file", file, "range", "--topic", object["topic"], "--from", "0",
                                      "--to", "9000000000000000000", "--limit", "100000", "--json"};
        if (!object["key"].get<std::string>().empty()) argv.insert(argv.end(), {"--key", object["key"]});
        Process range(argv);
        if (range.wait(std::chrono::seconds(60)) != 0) {
            out += "cpm history range of " + object["name"].get<std::string>() + ": " + range.errors();
            continue;
        }
        for (const auto& s : json_lines(range.output())) {
            if (!s.contains("commit_ns")) continue;
            ++ours;
            const std::string where = object["name"].get<std::string>() + " at commit " + std::to_string(s["commit_ns"].get<uint64_t>());
            auto [from, to] = by_time.equal_range({object["topic"], std::to_string(s["commit_ns"].get<uint64_t>())});
            if (from == to) {
                out += where + ": no message with that log time in the reference reader's\n";
                continue;
            }
            std::string best;
            for (auto it = from; it != to; ++it) {
                const nlohmann::json& m = *it->second;
                std::string d = object["data_time"] == "create_stamp" && m["publish_time"] != std::to_string(s["data_ns"].get<uint64_t>())
                                    ? "publish_time " + m["publish_time"].get<std::string>() + " is not the data time\n"
                                    : "";
                if (s.contains("data")) d += differs(s["data"], m["data"], "data");
                else if (!m["data"].is_null()) d += "the reference reader decodes it, cpm does not\n";
                if (d.empty() || it == from) best = d;
                if (d.empty()) break;
            }
            if (!best.empty()) out += where + ":\n" + best;
        }
    }
    if (ours != theirs.size()) {
        out += "cpm answers " + std::to_string(ours) + " samples, the reference reader read " + std::to_string(theirs.size()) + " messages\n";
    }
    if (totals["schemas"] == 0 && !theirs.empty()) out += "no schema in the file\n";
    return out.size() > 4000 ? out.substr(0, 4000) + "…\n" : out;
}

}  // namespace cpm_test
