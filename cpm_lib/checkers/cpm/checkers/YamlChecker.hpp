#pragma once
// cpm's checker over a YAML document (scenarios, camera files): the same findings as the JSON
// checker, with each one's line. Internal to cpm's libraries: not installed.
#include <cpm/CommandLine.hpp>
#include <cpm/Diagnostics.hpp>

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

namespace cpm::checkers {

/// Each method checks one node at a YAML path (`vehicles[0].start`), records what is wrong with
/// its line, and returns nullopt then, so that a loader reports every error at once.
class YamlChecker : public Checker
{
public:
    using Checker::Checker;
    using Checker::error;

    static int line_of(const YAML::Node& at) { return at.IsDefined() ? at.Mark().line + 1 : 0; }

    void error(const YAML::Node& at, const std::string& path, const std::string& message) { Checker::error(path, message, line_of(at)); }
    void warning(const YAML::Node& at, const std::string& path, const std::string& message) { Checker::warning(path, message, line_of(at)); }

    /// Every key of a map must be one of `known` (with "did you mean" for a typo).
    void keys(const YAML::Node& map, const std::string& path, const std::vector<std::string>& known)
    {
        for (const auto& kv : map) {
            const std::string key = kv.first.as<std::string>("");
            if (std::find(known.begin(), known.end(), key) != known.end()) continue;
            unknown_key(path.empty() ? key : path + "." + key, key, known, line_of(kv.first));
        }
    }
    std::optional<std::string> text(const YAML::Node& n, const std::string& path)
    {
        if (!n.IsScalar()) {
            error(n, path, "expected a text");
            return std::nullopt;
        }
        return n.as<std::string>();
    }
    std::optional<double> number(const YAML::Node& n, const std::string& path)
    {
        double v = 0;
        if (!n.IsScalar() || !YAML::convert<double>::decode(n, v) || !std::isfinite(v)) {
            error(n, path, "'" + shown(n) + "' is not a finite number");
            return std::nullopt;
        }
        return v;
    }
    /// A finite number in [min, max].
    std::optional<double> number(const YAML::Node& n, const std::string& path, double min, double max)
    {
        const auto v = number(n, path);
        if (v && (*v < min || *v > max)) {
            error(n, path, shown(n) + " is out of range (" + shown_number(min) + " to " + shown_number(max) + ")");
            return std::nullopt;
        }
        return v;
    }
    static std::string shown_number(double v)
    {
        std::ostringstream s;
        s << v;
        return s.str();
    }
    std::optional<long long> integer(const YAML::Node& n, const std::string& path, long long min, long long max)
    {
        long long v = 0;
        if (!n.IsScalar() || !YAML::convert<long long>::decode(n, v)) {
            error(n, path, "'" + shown(n) + "' is not a whole number");
            return std::nullopt;
        }
        if (v < min || v > max) {
            error(n, path, std::to_string(v) + " is out of range (" + std::to_string(min) + " to " + std::to_string(max) + ")");
            return std::nullopt;
        }
        return v;
    }
    std::optional<bool> boolean(const YAML::Node& n, const std::string& path)
    {
        bool v = false;
        if (!n.IsScalar() || !YAML::convert<bool>::decode(n, v)) {
            error(n, path, "expected true or false");
            return std::nullopt;
        }
        return v;
    }
    /// "30s", "400ms", …, longer than 0.
    std::optional<uint64_t> duration(const YAML::Node& n, const std::string& path)
    {
        const auto t = text(n, path);
        if (!t) return std::nullopt;
        try {
            const uint64_t d = cpm::cli::parse_duration(path, *t);
            if (d == 0) {
                error(n, path, "must be longer than 0");
                return std::nullopt;
            }
            return d;
        } catch (const std::exception&) {
            error(n, path, "'" + *t + "' is not a duration (a number with ns, us, ms, s, m or h: 30s, 400ms)");
            return std::nullopt;
        }
    }
    /// A file named relative to `dir`, which must exist; its canonical path, or "" (an error said).
    std::string file(const YAML::Node& n, const std::string& path, const std::string& dir, const std::string& what)
    {
        namespace fs = std::filesystem;
        const auto t = text(n, path);
        if (!t) return "";
        const fs::path p = fs::path(*t).is_absolute() ? fs::path(*t) : fs::path(dir) / *t;
        std::error_code ec;
        if (fs::is_directory(p, ec)) {
            error(n, path, what + " '" + *t + "' is a directory (" + p.lexically_normal().string() + "), not a file");
            return "";
        }
        if (!fs::is_regular_file(p, ec)) {
            error(n, path, what + " '" + *t + "' does not exist (looked for " + p.lexically_normal().string() + ")");
            return "";
        }
        return fs::weakly_canonical(p).string();
    }

private:
    static std::string shown(const YAML::Node& n) { return n.IsScalar() ? n.as<std::string>() : std::string("…"); }
};

}  // namespace cpm::checkers
