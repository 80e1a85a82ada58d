#pragma once
// Decodes a serialized sample (plain CDR, XCDR1, encapsulation header included) field by field
// into JSON, from the lab's IDL files read at run time: structs, enums, arrays, sequences,
// strings and primitives — what cpm's types use. A type it does not know is left to the caller.
#include <nlohmann/json.hpp>

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace cpm::tools {

class IdlDecoder
{
public:
    /// Reads every *.idl in `dir`; throws std::runtime_error naming file and line on a
    /// construct it cannot read.
    explicit IdlDecoder(const std::string& dir);
    bool knows(const std::string& type_name) const { return structs_.count(type_name) != 0; }
    /// The sample as JSON; nullopt when the bytes do not decode as the type.
    std::optional<nlohmann::json> decode(const std::string& type_name, const std::vector<uint8_t>& payload) const;

private:
    struct Member
    {
        std::string name, type;  // type: a primitive, "string", a struct or enum name, "sequence<T>"
        size_t array = 0;        // > 0: a fixed array of that many
    };
    void parse(const std::string& text, const std::string& file);
    nlohmann::json read(const std::string& type, class CdrCursor& c) const;

    std::map<std::string, std::vector<Member>> structs_;
    std::map<std::string, std::vector<std::string>> enums_;
};

}  // namespace cpm::tools
