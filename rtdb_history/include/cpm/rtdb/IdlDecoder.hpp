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

namespace cpm::rtdb {

class IdlDecoder
{
public:
    /// Reads every *.idl in `dir`; throws cpm::Error naming file and line on a
    /// construct it cannot read.
    explicit IdlDecoder(const std::string& dir);
    /// From IDL texts (file name → text), as a recording carries them.
    explicit IdlDecoder(const std::map<std::string, std::string>& sources);
    /// The lab's own types: the IDL folder named by CPM_IDL_DIR, else the source tree's, else
    /// the installed one; nullptr when none can be read. Built once, then shared (read-only).
    static const IdlDecoder* lab_types();

    /// The IDL texts read, by file name (without the folder).
    const std::map<std::string, std::string>& sources() const { return sources_; }

    bool knows(const std::string& type_name) const { return structs_.count(type_name) != 0; }
    /// The sample as JSON; nullopt when the bytes do not decode as the type.
    std::optional<nlohmann::json> decode(const std::string& type_name, const std::vector<uint8_t>& payload) const;
    std::optional<nlohmann::json> decode(const std::string& type_name, const uint8_t* data, size_t size) const;
    /// The reverse of decode(): the sample as a writer puts it on the wire (XCDR1 little endian,
    /// encapsulation header included) from JSON shaped as decode() gives it. Lenient where text
    /// comes in: a number given as a string ("0.5", "nan", "inf"), an enum by name or number, a
    /// missing member as its zero. Throws cpm::Error naming the member path (e.g.
    /// "pose.x") and the value for anything that does not fit the type.
    std::vector<uint8_t> encode(const std::string& type_name, const nlohmann::json& sample) const;

    /// Whether the type begins with `Header header` (create_stamp, valid_after_stamp); false
    /// for a type it does not know.
    bool has_header(const std::string& type_name) const;
    /// The names of the type's @key members, in order (none: an unkeyed or unknown type).
    std::vector<std::string> key_members(const std::string& type_name) const;
    /// A sample for people and scripts: {"data": {…fields…}} when the type is known and the bytes
    /// decode, else {"payload_base64": "…"}.
    nlohmann::json describe(const std::string& type_name, const std::vector<uint8_t>& payload) const;

    /// The type's fields by path in IDL member order ("header.create_stamp.nanoseconds",
    /// "pose.x"): nested structs opened, an array or sequence one path. Empty for an unknown type.
    std::vector<std::string> field_paths(const std::string& type_name) const;

    /// The IDL type of a struct's member ("octet", "string", "sequence<double>", …); "" if none.
    std::string member_type(const std::string& type_name, const std::string& member) const;
    /// The instance key of a sample as text: the @key members' values, strings as they are,
    /// several joined by ','; nullopt for an unknown or unkeyed type or bytes that do not decode.
    std::optional<std::string> key_text(const std::string& type_name, const uint8_t* data, size_t size) const;

    /// The instance's key as DDS hashes it (XTypes 1.3 §7.6.8): the @key members serialized as
    /// big-endian CDR; `md5` says whether the key's largest possible size exceeds 16 bytes (a
    /// string key), when the hash is the MD5 of these bytes, else the bytes zero-padded to 16.
    struct KeyBytes
    {
        std::vector<uint8_t> bytes;
        bool md5 = false;
    };
    /// nullopt for an unknown or unkeyed type, a key member of a kind it cannot serialize
    /// (structs, sequences) or bytes that do not decode.
    std::optional<KeyBytes> key_bytes(const std::string& type_name, const uint8_t* data, size_t size) const;

private:
    friend class IdlParser;  // reads the IDL text into structs_ and enums_
    struct Member
    {
        std::string name, type;  // type: a primitive, "string", a struct or enum name, "sequence<T>"
        size_t array = 0;        // > 0: a fixed array of that many
        bool key = false;        // @key
    };
    nlohmann::json read(const std::string& type, class CdrCursor& c) const;
    void write(const std::string& type, const nlohmann::json& v, class CdrWriter& w, const std::string& path) const;

    std::map<std::string, std::vector<Member>> structs_;
    std::map<std::string, std::vector<std::string>> enums_;
    std::map<std::string, std::string> sources_;
};

/// describe() with the lab's IDL when there is one (`types` may be null: then the bytes).
nlohmann::json describe(const IdlDecoder* types, const std::string& type_name, const std::vector<uint8_t>& payload);
/// RFC 4648 base64 of the bytes, with padding (cpm::base64_encode).
std::string base64(const std::vector<uint8_t>& bytes);

}  // namespace cpm::rtdb
