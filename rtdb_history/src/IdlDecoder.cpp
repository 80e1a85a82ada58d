#include <cpm/rtdb/IdlDecoder.hpp>

#include <cpm/Error.hpp>
#include <cpm/base64.hpp>
#include <cpm/read_text_file.hpp>

#include "CdrCursor.hpp"
#include "CdrWriter.hpp"
#include "IdlParser.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <memory>
#include <optional>
#include <sys/stat.h>
#include <dirent.h>
#include <stdexcept>
#include <type_traits>

namespace cpm::rtdb {

namespace {

/// A JSON scalar as a number of type T: numbers as they are, text parsed ("0.5", "nan", "-inf",
/// "true"); anything else, or out of T's range, throws naming the path.
template <typename T>
T number_of(const nlohmann::json& v, const std::string& path)
{
    auto bad = [&](const std::string& why) {
        return Error(path + ": " + (v.is_string() ? "'" + v.get<std::string>() + "'" : v.dump()) + " " + why);
    };
    long double x = 0;
    if (v.is_null()) return T{};
    if (v.is_boolean()) x = v.get<bool>() ? 1 : 0;
    else if (v.is_number_unsigned()) x = (long double)v.get<uint64_t>();
    else if (v.is_number_integer()) x = (long double)v.get<int64_t>();
    else if (v.is_number_float()) x = v.get<double>();
    else if (v.is_string()) {
        const std::string t = v.get<std::string>();
        if (t == "true") return T(1);
        if (t == "false") return T(0);
        if constexpr (std::is_integral_v<T>) {
            errno = 0;
            char* end = nullptr;
            if (std::is_signed_v<T>) {
                const long long n = std::strtoll(t.c_str(), &end, 10);
                if (t.empty() || *end || errno) throw bad("is not a whole number");
                x = (long double)n;
            } else {
                if (!t.empty() && t[0] == '-') throw bad("is negative");
                const unsigned long long n = std::strtoull(t.c_str(), &end, 10);
                if (t.empty() || *end || errno) throw bad("is not a whole number");
                if (n > std::numeric_limits<T>::max()) throw bad("is out of range");
                return T(n);
            }
        } else {
            char* end = nullptr;
            x = std::strtold(t.c_str(), &end);
            if (t.empty() || *end) throw bad("is not a number");
        }
    } else {
        throw bad("is not a number");
    }
    if constexpr (std::is_integral_v<T>) {
        if (x != std::floor(x)) throw bad("is not a whole number");
        if (x < (long double)std::numeric_limits<T>::min() || x > (long double)std::numeric_limits<T>::max()) throw bad("is out of range");
        if (v.is_number_unsigned()) return T(v.get<uint64_t>());  // exact for 64-bit values
        if (v.is_number_integer()) return T(v.get<int64_t>());
    }
    return T(x);
}

}  // namespace

void IdlDecoder::write(const std::string& type, const nlohmann::json& v, CdrWriter& w, const std::string& path) const
{
    if (type == "boolean") return w.put<uint8_t>(number_of<uint8_t>(v, path) != 0);
    if (type == "octet" || type == "char") return w.put<uint8_t>(number_of<uint8_t>(v, path));
    if (type == "short") return w.put<int16_t>(number_of<int16_t>(v, path));
    if (type == "unsigned short") return w.put<uint16_t>(number_of<uint16_t>(v, path));
    if (type == "long") return w.put<int32_t>(number_of<int32_t>(v, path));
    if (type == "unsigned long") return w.put<uint32_t>(number_of<uint32_t>(v, path));
    if (type == "long long") return w.put<int64_t>(number_of<int64_t>(v, path));
    if (type == "unsigned long long") return w.put<uint64_t>(number_of<uint64_t>(v, path));
    if (type == "float") return w.put<float>(number_of<float>(v, path));
    if (type == "double") return w.put<double>(number_of<double>(v, path));
    if (type == "string") return w.string(v.is_null() ? "" : v.is_string() ? v.get<std::string>() : v.dump());
    if (type.rfind("sequence", 0) == 0) {
        const auto seq = sequence_of(type);
        if (!seq) throw Error(path + ": cannot write type " + type);
        nlohmann::json items = v.is_null() ? nlohmann::json::array() : v;
        if (items.is_string()) {
            try {
                items = nlohmann::json::parse(items.get<std::string>());
            } catch (const std::exception&) {
                throw Error(path + ": '" + v.get<std::string>() + "' is not a JSON array");
            }
        }
        if (!items.is_array()) throw Error(path + ": " + v.dump() + " is not an array");
        if (seq->bound && items.size() > *seq->bound) throw Error(path + ": " + std::to_string(items.size()) + " items, at most " + std::to_string(*seq->bound));
        w.put<uint32_t>(uint32_t(items.size()));
        for (size_t i = 0; i < items.size(); ++i) write(seq->element, items[i], w, path + "[" + std::to_string(i) + "]");
        return;
    }
    if (auto e = enums_.find(type); e != enums_.end()) {
        if (v.is_string()) {
            auto it = std::find(e->second.begin(), e->second.end(), v.get<std::string>());
            if (it != e->second.end()) return w.put<uint32_t>(uint32_t(it - e->second.begin()));
        }
        const uint32_t n = number_of<uint32_t>(v, path);
        if (n >= e->second.size()) throw Error(path + ": " + v.dump() + " is no " + type);
        return w.put<uint32_t>(n);
    }
    auto s = structs_.find(type);
    if (s == structs_.end()) throw Error(path + ": unknown type " + type);
    if (!v.is_null() && !v.is_object()) throw Error(path + ": " + v.dump() + " is not a " + type);
    for (const auto& m : s->second) {
        const std::string p = path.empty() ? m.name : path + "." + m.name;
        const nlohmann::json& mv = v.is_object() && v.contains(m.name) ? v[m.name] : nlohmann::json();
        if (m.array) {
            nlohmann::json items = mv;
            if (items.is_string()) {
                try {
                    items = nlohmann::json::parse(items.get<std::string>());
                } catch (const std::exception&) {
                    throw Error(p + ": '" + mv.get<std::string>() + "' is not a JSON array");
                }
            }
            if (!items.is_null() && (!items.is_array() || items.size() != m.array))
                throw Error(p + ": expected " + std::to_string(m.array) + " items, got " + items.dump());
            for (size_t i = 0; i < m.array; ++i) write(m.type, items.is_null() ? nlohmann::json() : items[i], w, p + "[" + std::to_string(i) + "]");
        } else {
            write(m.type, mv, w, p);
        }
    }
}

std::vector<std::string> IdlDecoder::field_paths(const std::string& type_name) const
{
    std::vector<std::string> out;
    auto s = structs_.find(type_name);
    if (s == structs_.end()) return out;
    for (const auto& m : s->second) {
        const bool nested = !m.array && structs_.count(m.type);
        if (!nested) {
            out.push_back(m.name);
            continue;
        }
        for (const auto& p : field_paths(m.type)) out.push_back(m.name + "." + p);
    }
    return out;
}

std::vector<uint8_t> IdlDecoder::encode(const std::string& type_name, const nlohmann::json& sample) const
{
    if (!knows(type_name)) throw Error("unknown type " + type_name);
    CdrWriter w;
    write(type_name, sample, w, "");
    return w.bytes();
}

IdlDecoder::IdlDecoder(const std::string& dir)
{
    DIR* d = ::opendir(dir.c_str());
    if (!d) throw Error("cannot read the IDL folder " + dir);
    std::vector<std::string> files;
    while (dirent* e = ::readdir(d)) {
        std::string name = e->d_name;
        if (name.size() > 4 && name.substr(name.size() - 4) == ".idl") files.push_back(dir + "/" + name);
    }
    ::closedir(d);
    for (const auto& f : files) {
        std::string text = read_text_file(f, "IDL file");
        IdlParser(text, f).read_into(structs_, enums_);
        sources_[f.substr(dir.size() + 1)] = std::move(text);
    }
}

IdlDecoder::IdlDecoder(const std::map<std::string, std::string>& sources)
{
    for (const auto& [file, text] : sources) IdlParser(text, file).read_into(structs_, enums_);
    sources_ = sources;
}

namespace {

/// A string member as JSON text can carry it: bytes that are not UTF-8 (a sender's own encoding)
/// become U+FFFD, so that printing the sample never fails.
std::string as_utf8(std::string s)
{
    if (std::all_of(s.begin(), s.end(), [](char ch) { return static_cast<unsigned char>(ch) < 0x80; })) return s;
    const auto text = nlohmann::json(s).dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
    return nlohmann::json::parse(text).get<std::string>();
}

}  // namespace

nlohmann::json IdlDecoder::read(const std::string& type, CdrCursor& c) const
{
    if (type == "boolean") return c.get<uint8_t>() != 0;
    if (type == "octet" || type == "char") return c.get<uint8_t>();
    if (type == "short") return c.get<int16_t>();
    if (type == "unsigned short") return c.get<uint16_t>();
    if (type == "long") return c.get<int32_t>();
    if (type == "unsigned long") return c.get<uint32_t>();
    if (type == "long long") return c.get<int64_t>();
    if (type == "unsigned long long") return c.get<uint64_t>();
    if (type == "float") return c.get<float>();
    if (type == "double") return c.get<double>();
    if (type == "string") return as_utf8(c.string());
    if (type.rfind("sequence", 0) == 0) {
        const auto seq = sequence_of(type);
        if (!seq) throw Error("cannot read type " + type);
        const uint32_t n = c.get<uint32_t>();
        nlohmann::json out = nlohmann::json::array();
        if (seq->bound && n > *seq->bound) throw Error("a sequence of " + std::to_string(n) + " items, at most " + std::to_string(*seq->bound));
        for (uint32_t i = 0; i < n; ++i) out.push_back(read(seq->element, c));
        return out;
    }
    if (auto e = enums_.find(type); e != enums_.end()) {
        const uint32_t v = c.get<uint32_t>();
        return v < e->second.size() ? nlohmann::json(e->second[v]) : nlohmann::json(v);
    }
    auto s = structs_.find(type);
    if (s == structs_.end()) throw Error("unknown type " + type);
    nlohmann::json out = nlohmann::json::object();
    for (const auto& m : s->second) {
        if (m.array) {
            nlohmann::json arr = nlohmann::json::array();
            for (size_t i = 0; i < m.array; ++i) arr.push_back(read(m.type, c));
            out[m.name] = arr;
        } else {
            out[m.name] = read(m.type, c);
        }
    }
    return out;
}

std::optional<nlohmann::json> IdlDecoder::decode(const std::string& type_name, const std::vector<uint8_t>& payload) const
{
    return decode(type_name, payload.data(), payload.size());
}

std::optional<nlohmann::json> IdlDecoder::decode(const std::string& type_name, const uint8_t* data, size_t size) const
{
    if (!knows(type_name)) return std::nullopt;
    CdrCursor c(data, size);
    if (!c.ok()) return std::nullopt;
    try {
        return read(type_name, c);
    } catch (const std::exception&) {
        return std::nullopt;
    }
}

bool IdlDecoder::has_header(const std::string& type_name) const
{
    auto s = structs_.find(type_name);
    return s != structs_.end() && !s->second.empty() && s->second[0].name == "header" && s->second[0].type == "Header";
}

std::vector<std::string> IdlDecoder::key_members(const std::string& type_name) const
{
    std::vector<std::string> out;
    if (auto s = structs_.find(type_name); s != structs_.end()) {
        for (const auto& m : s->second) {
            if (m.key) out.push_back(m.name);
        }
    }
    return out;
}

std::string IdlDecoder::member_type(const std::string& type_name, const std::string& member) const
{
    if (auto s = structs_.find(type_name); s != structs_.end()) {
        for (const auto& m : s->second) {
            if (m.name == member) return m.type;
        }
    }
    return "";
}

std::optional<std::string> IdlDecoder::key_text(const std::string& type_name, const uint8_t* data, size_t size) const
{
    const auto keys = key_members(type_name);
    if (keys.empty()) return std::nullopt;
    auto sample = decode(type_name, data, size);
    if (!sample) return std::nullopt;
    std::string text;
    for (const auto& k : keys) {
        const auto& v = (*sample)[k];
        text += (text.empty() ? "" : ",") + (v.is_string() ? v.get<std::string>() : v.dump());
    }
    return text;
}

std::optional<IdlDecoder::KeyBytes> IdlDecoder::key_bytes(const std::string& type_name, const uint8_t* data,
                                                          size_t size) const
{
    const auto keys = key_members(type_name);
    if (keys.empty()) return std::nullopt;
    auto sample = decode(type_name, data, size);
    if (!sample) return std::nullopt;
    static const std::map<std::string, size_t> kSizes{
        {"boolean", 1}, {"octet", 1},  {"char", 1},          {"short", 2}, {"unsigned short", 2}, {"long", 4},
        {"unsigned long", 4}, {"float", 4}, {"long long", 8}, {"unsigned long long", 8}, {"double", 8}};
    KeyBytes out;
    size_t max_size = 0;
    auto align = [&](size_t n) {
        while (out.bytes.size() % n) out.bytes.push_back(0);
        max_size = (max_size + n - 1) / n * n;
    };
    auto put = [&](uint64_t bits, size_t n) {
        align(n);
        for (size_t i = 0; i < n; ++i) out.bytes.push_back(uint8_t(bits >> (8 * (n - 1 - i))));
        max_size += n;
    };
    for (const auto& k : keys) {
        const std::string type = member_type(type_name, k);
        const auto& v = (*sample)[k];
        if (type == "string") {
            const std::string text = v.get<std::string>();
            put(text.size() + 1, 4);
            out.bytes.insert(out.bytes.end(), text.begin(), text.end());
            out.bytes.push_back(0);
            max_size = SIZE_MAX / 2;  // unbounded
        } else if (auto e = enums_.find(type); e != enums_.end()) {
            const auto at = std::find(e->second.begin(), e->second.end(), v.is_string() ? v.get<std::string>() : "");
            put(at != e->second.end() ? uint64_t(at - e->second.begin()) : v.get<uint64_t>(), 4);
        } else if (auto n = kSizes.find(type); n != kSizes.end()) {
            uint64_t bits = 0;
            if (type == "double") {
                const double d = v.get<double>();
                std::memcpy(&bits, &d, 8);
            } else if (type == "float") {
                const float f = v.get<float>();
                uint32_t b32 = 0;
                std::memcpy(&b32, &f, 4);
                bits = b32;
            } else if (v.is_boolean()) {
                bits = v.get<bool>() ? 1 : 0;
            } else {
                bits = v.is_number_unsigned() ? v.get<uint64_t>() : uint64_t(v.get<int64_t>());
            }
            put(bits, n->second);
        } else {
            return std::nullopt;
        }
    }
    out.md5 = max_size > 16;
    return out;
}

nlohmann::json IdlDecoder::describe(const std::string& type_name, const std::vector<uint8_t>& payload) const
{
    if (auto data = decode(type_name, payload)) return {{"data", *data}};
    return {{"payload_base64", base64(payload)}};
}

nlohmann::json describe(const IdlDecoder* types, const std::string& type_name, const std::vector<uint8_t>& payload)
{
    if (types) return types->describe(type_name, payload);
    return {{"payload_base64", base64(payload)}};
}

std::string base64(const std::vector<uint8_t>& bytes) { return cpm::base64_encode(bytes); }

const IdlDecoder* IdlDecoder::lab_types()
{
    static const std::unique_ptr<IdlDecoder> types = []() -> std::unique_ptr<IdlDecoder> {
        std::vector<std::string> dirs;
        if (const char* env = std::getenv("CPM_IDL_DIR")) dirs.push_back(env);
        dirs.push_back(CPM_IDL_SOURCE_DIR);
        dirs.push_back(CPM_IDL_INSTALL_DIR);
        for (const auto& dir : dirs) {
            struct stat st{};
            if (::stat(dir.c_str(), &st) != 0 || !S_ISDIR(st.st_mode)) continue;
            try {
                return std::make_unique<IdlDecoder>(dir);
            } catch (const std::exception&) {
                continue;  // unreadable: try the next place
            }
        }
        return nullptr;
    }();
    return types.get();
}

}  // namespace cpm::rtdb
