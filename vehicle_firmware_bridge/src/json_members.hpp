#pragma once
// Reads a flat JSON object of named numbers for parameter and calibration files: every
// member must be known, of the right type and within its bounds; errors name file and member.
#include <cpm/Error.hpp>

#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <cpm/read_text_file.hpp>

#include <limits>
#include <set>
#include <sstream>
#include <string>

namespace cpm::vehicle {

using cpm::read_text_file;

class JsonMembers
{
public:
    JsonMembers(const std::string& json_text, std::string source) : source_(std::move(source))
    {
        try {
            json_ = nlohmann::json::parse(json_text);
        } catch (const nlohmann::json::exception& e) {
            throw Error(source_ + ": not valid JSON (" + e.what() + ")");
        }
        if (!json_.is_object()) throw Error(source_ + ": expected a JSON object of named values");
    }

    /// Sets `value` from member `name` when present; min/max are inclusive bounds.
    void number(const std::string& name, double& value, double min,
                double max = std::numeric_limits<double>::infinity())
    {
        known_.insert(name);
        if (!json_.contains(name)) return;
        value = checked_number(json_[name], name);
        if (value < min || value > max) {
            throw Error(source_ + ": " + name + " = " + json_[name].dump() + " is out of range [" + std::to_string(min) +
                        ", " + std::to_string(max) + "]");
        }
    }

    /// Sets three numbers from a member `name` that holds `[a, b, c]`.
    void triple(const std::string& name, double& a, double& b, double& c)
    {
        known_.insert(name);
        if (!json_.contains(name)) return;
        const auto& j = json_[name];
        if (!j.is_array() || j.size() != 3) throw Error(source_ + ": " + name + ": expected [x, y, yaw], got " + j.dump());
        a = checked_number(j[0], name + "[0]");
        b = checked_number(j[1], name + "[1]");
        c = checked_number(j[2], name + "[2]");
    }

    /// Throws when the object has a member nobody asked for (a typo would else go unnoticed).
    void finish() const
    {
        for (auto it = json_.begin(); it != json_.end(); ++it) {
            if (!known_.count(it.key())) {
                std::string list;
                for (const auto& k : known_) list += (list.empty() ? "" : ", ") + k;
                throw Error(source_ + ": unknown member \"" + it.key() + "\" (known: " + list + ")");
            }
        }
    }

private:
    double checked_number(const nlohmann::json& j, const std::string& name) const
    {
        if (!j.is_number() || !std::isfinite(j.get<double>())) {
            throw Error(source_ + ": " + name + ": expected a number, got " + j.dump());
        }
        return j.get<double>();
    }

    std::string source_;
    nlohmann::json json_;
    std::set<std::string> known_;
};

}  // namespace cpm::vehicle
