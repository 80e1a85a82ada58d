#pragma once
// Reads a flat JSON object of named numbers for parameter and calibration files: every
// member must be known, of the right type and within its bounds. finish() throws a
// cpm::FileError with every error at once, each naming file and member.
#include <cpm/checkers/JsonChecker.hpp>
#include <cpm/read_text_file.hpp>

#include <limits>
#include <string>
#include <vector>

namespace cpm::vehicle {

using cpm::read_text_file;

class JsonMembers
{
public:
    JsonMembers(const std::string& json_text, std::string source) : check_(std::move(source))
    {
        if (auto j = check_.parse(json_text)) json_ = std::move(*j);
        check_.throw_if_errors();
        if (!check_.object(json_, "$", "a JSON object of named values")) check_.throw_if_errors();
    }

    /// Sets `value` from member `name` when present; min/max are inclusive bounds.
    void number(const std::string& name, double& value, double min, double max = std::numeric_limits<double>::infinity())
    {
        known_.push_back(name);
        if (!json_.contains(name)) return;
        if (auto v = check_.number(json_[name], "$." + name, min, max)) value = *v;
    }

    /// Sets three numbers from a member `name` that holds `[a, b, c]`.
    void triple(const std::string& name, double& a, double& b, double& c)
    {
        known_.push_back(name);
        if (!json_.contains(name)) return;
        const auto& j = json_[name];
        if (!j.is_array() || j.size() != 3) {
            check_.error("$." + name, "expected [x, y, yaw], got " + j.dump());
            return;
        }
        double* out[] = {&a, &b, &c};
        for (size_t i = 0; i < 3; ++i) {
            if (auto v = check_.number(j[i], checkers::JsonChecker::item("$." + name, i))) *out[i] = *v;
        }
    }

    /// A rule between members (e.g. min < max), checked once each is read.
    void require(bool holds, const std::string& what)
    {
        if (!holds) check_.error("$", what);
    }

    /// Throws with every error, including a member nobody asked for (a typo would else go unnoticed).
    void finish()
    {
        check_.keys(json_, "$", known_);
        check_.throw_if_errors();
    }

private:
    checkers::JsonChecker check_;
    nlohmann::json json_;
    std::vector<std::string> known_;
};

}  // namespace cpm::vehicle
