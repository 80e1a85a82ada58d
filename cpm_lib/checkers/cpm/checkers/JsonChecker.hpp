#pragma once
// cpm's checker over a JSON document (state machines, lane graphs, worlds, parameter and
// calibration files). Internal to cpm's libraries: not installed.
#include <cpm/Diagnostics.hpp>

#include <nlohmann/json.hpp>

#include <cmath>
#include <limits>
#include <algorithm>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

namespace cpm::checkers {

/// Each method checks one value at a JSON path (`$.nodes[2].x`), records what is wrong, and
/// returns nullopt/false then, so that a loader goes on and reports every error at once.
class JsonChecker : public Checker
{
public:
    using json = nlohmann::json;
    using Checker::Checker;

    static std::string member(const std::string& path, const std::string& key) { return path + "." + key; }
    static std::string item(const std::string& path, size_t i) { return path + "[" + std::to_string(i) + "]"; }

    /// The document, or nullopt with "not valid JSON (…)".
    std::optional<json> parse(const std::string& text)
    {
        try {
            return json::parse(text);
        } catch (const json::exception& e) {
            error("", std::string("not valid JSON (") + e.what() + ")");
            return std::nullopt;
        }
    }
    /// Every member of `object` must be one of `known` (with "did you mean" for a typo).
    void keys(const json& object, const std::string& path, const std::vector<std::string>& known)
    {
        for (auto it = object.begin(); it != object.end(); ++it) {
            if (std::find(known.begin(), known.end(), it.key()) == known.end()) unknown_key(member(path, it.key()), it.key(), known);
        }
    }
    bool object(const json& v, const std::string& path, const std::string& expected)
    {
        if (v.is_object()) return true;
        error(path, "expected " + expected + ", got " + v.dump());
        return false;
    }
    bool array(const json& v, const std::string& path, const std::string& expected)
    {
        if (v.is_array()) return true;
        error(path, "expected " + expected + ", got " + v.dump());
        return false;
    }
    /// A finite number in [min, max].
    std::optional<double> number(const json& v, const std::string& path, double min = -std::numeric_limits<double>::infinity(),
                                 double max = std::numeric_limits<double>::infinity())
    {
        if (!v.is_number() || !std::isfinite(v.get<double>())) {
            error(path, "expected a finite number, got " + v.dump());
            return std::nullopt;
        }
        const double d = v.get<double>();
        if (d < min || d > max) {
            error(path, v.dump() + " is out of range [" + text_of(min) + ", " + text_of(max) + "]");
            return std::nullopt;
        }
        return d;
    }
    /// Member `key` of `parent`, a finite number; "missing" when absent.
    std::optional<double> number_member(const json& parent, const std::string& path, const std::string& key)
    {
        if (!parent.contains(key)) {
            error(path, "missing \"" + key + "\"");
            return std::nullopt;
        }
        return number(parent[key], member(path, key));
    }
    /// A whole number in [min, max] (ids are 32-bit: 4294967299 must not become 3).
    std::optional<long long> integer(const json& v, const std::string& path, long long min = std::numeric_limits<int>::min(),
                                     long long max = std::numeric_limits<int>::max())
    {
        const bool whole = v.is_number_integer() && !(v.is_number_unsigned() && v.get<uint64_t>() > uint64_t(max));
        if (!whole || v.get<long long>() < min || v.get<long long>() > max) {
            error(path, "expected an integer in " + std::to_string(min) + ".." + std::to_string(max) + ", got " + v.dump());
            return std::nullopt;
        }
        return v.get<long long>();
    }

private:
    static std::string text_of(double v)
    {
        if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
        std::ostringstream s;
        s << v;
        return s.str();
    }
};

}  // namespace cpm::checkers
