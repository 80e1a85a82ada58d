#include <cpm/rtdb/IdlDecoder.hpp>

#include <cpm/base64.hpp>

#include <cpm/read_text_file.hpp>

#include <algorithm>
#include <cctype>
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
#include <sstream>
#include <stdexcept>
#include <type_traits>

namespace cpm::rtdb {

/// Reads plain CDR: each primitive aligned to its size from the start of the data (after the
/// 4-byte encapsulation header), in the encapsulation's byte order.
class CdrCursor
{
public:
    CdrCursor(const uint8_t* data, size_t size) : b_(data), size_(size), little_(size >= 2 && (data[1] & 1)) {}
    template <typename T>
    T get()
    {
        align(sizeof(T));
        need(sizeof(T));
        uint8_t raw[sizeof(T)];
        for (size_t i = 0; i < sizeof(T); ++i) raw[i] = b_[at_ + (little_ ? i : sizeof(T) - 1 - i)];
        at_ += sizeof(T);
        T v;
        std::memcpy(&v, raw, sizeof(T));
        return v;
    }
    std::string string()
    {
        const uint32_t n = get<uint32_t>();
        need(n);
        std::string s(reinterpret_cast<const char*>(b_ + at_), n ? n - 1 : 0);
        at_ += n;
        return s;
    }
    bool ok() const { return size_ >= 4; }

private:
    void align(size_t n) { at_ = 4 + (at_ - 4 + n - 1) / n * n; }
    void need(size_t n)
    {
        if (n > size_ || at_ > size_ - n) throw std::out_of_range("payload ends early");
    }
    const uint8_t* b_;
    size_t size_;
    bool little_;
    size_t at_ = 4;
};

/// Writes XCDR1 little endian after a 4-byte encapsulation header; alignment counts from after it.
class CdrWriter
{
public:
    CdrWriter() : b_{0x00, 0x01, 0x00, 0x00} {}
    template <typename T>
    void put(T v)
    {
        while ((b_.size() - 4) % sizeof(T)) b_.push_back(0);
        uint8_t raw[sizeof(T)];
        std::memcpy(raw, &v, sizeof(T));  // little endian host (x86, ARM)
        b_.insert(b_.end(), raw, raw + sizeof(T));
    }
    void string(const std::string& s)
    {
        put<uint32_t>(uint32_t(s.size() + 1));
        b_.insert(b_.end(), s.begin(), s.end());
        b_.push_back(0);
    }
    std::vector<uint8_t> bytes() { return std::move(b_); }

private:
    std::vector<uint8_t> b_;
};

namespace {

/// A JSON scalar as a number of type T: numbers as they are, text parsed ("0.5", "nan", "-inf",
/// "true"); anything else, or out of T's range, throws naming the path.
template <typename T>
T number_of(const nlohmann::json& v, const std::string& path)
{
    auto bad = [&](const std::string& why) {
        return std::invalid_argument(path + ": " + (v.is_string() ? "'" + v.get<std::string>() + "'" : v.dump()) + " " + why);
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

namespace {

bool is_word_char(char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '_'; }
bool is_space(char c) { return std::isspace(static_cast<unsigned char>(c)) != 0; }

std::string trimmed(const std::string& s)
{
    const auto a = s.find_first_not_of(" \t\r\n");
    if (a == std::string::npos) return "";
    return s.substr(a, s.find_last_not_of(" \t\r\n") - a + 1);
}

/// Runs of white space as one space.
std::string collapsed(const std::string& s)
{
    std::string out;
    for (char c : s) {
        if (!is_space(c)) out += c;
        else if (out.empty() || out.back() != ' ') out += ' ';
    }
    return out;
}

bool iequals(const std::string& a, const char* b)
{
    const std::string lb(b);
    return a.size() == lb.size() &&
           std::equal(a.begin(), a.end(), lb.begin(), [](char x, char y) { return std::tolower(static_cast<unsigned char>(x)) == y; });
}

constexpr const char* kKeyMark = "KEY_MEMBER";

/// The IDL text without comments, preprocessor lines and annotations (@key becomes KEY_MEMBER):
/// each turned into spaces, newlines kept, so that an offset still has its line.
std::string cleaned_idl(const std::string& text, const std::string& file)
{
    std::string out;
    out.reserve(text.size());
    bool line_start = true;
    for (size_t i = 0; i < text.size();) {
        const char c = text[i];
        if (line_start && c == '#') {  // a preprocessor line
            while (i < text.size() && text[i] != '\n') ++i;
            continue;
        }
        if (c == '/' && i + 1 < text.size() && text[i + 1] == '/') {
            while (i < text.size() && text[i] != '\n') ++i;
            continue;
        }
        if (c == '/' && i + 1 < text.size() && text[i + 1] == '*') {
            const size_t close = text.find("*/", i + 2);
            if (close == std::string::npos) {
                throw std::runtime_error(file + ":" + std::to_string(1 + std::count(text.begin(), text.begin() + long(i), '\n')) +
                                         ": a /* comment that never ends");
            }
            for (; i < close + 2; ++i) out += text[i] == '\n' ? '\n' : ' ';
            continue;
        }
        if (c == '@') {
            size_t j = i + 1;
            while (j < text.size() && is_word_char(text[j])) ++j;
            const std::string name = text.substr(i + 1, j - i - 1);
            std::string argument;
            size_t k = j;
            while (k < text.size() && (text[k] == ' ' || text[k] == '\t')) ++k;
            if (k < text.size() && text[k] == '(') {
                const size_t close = text.find(')', k);
                if (close != std::string::npos && text.find('\n', k) > close) {
                    argument = trimmed(text.substr(k + 1, close - k - 1));
                    j = close + 1;
                }
            }
            const bool key = iequals(name, "key") && (argument.empty() || iequals(argument, "true"));
            out += key ? std::string(" ") + kKeyMark + " " : " ";
            i = j;
            line_start = false;
            continue;
        }
        out += c;
        if (c == '\n') line_start = true;
        else if (!is_space(c)) line_start = false;
        ++i;
    }
    return out;
}

struct SequenceType
{
    std::string element;
    std::optional<uint64_t> bound;
};

/// "sequence<T>" or "sequence<T, N>" (spaces anywhere between); nullopt for any other type.
std::optional<SequenceType> sequence_of(const std::string& type)
{
    if (type.rfind("sequence", 0) != 0) return std::nullopt;
    const size_t open = type.find_first_not_of(" \t", 8);
    if (open == std::string::npos || type[open] != '<') return std::nullopt;
    const size_t close = type.find('>', open);
    if (close == std::string::npos || type.find_first_not_of(" \t", close + 1) != std::string::npos) return std::nullopt;
    const std::string inner = type.substr(open + 1, close - open - 1);
    const size_t comma = inner.find(',');
    SequenceType out{trimmed(inner.substr(0, comma)), std::nullopt};
    if (out.element.empty()) return std::nullopt;
    if (comma != std::string::npos) {
        const std::string bound = trimmed(inner.substr(comma + 1));
        if (bound.empty() || bound.size() > 10 || !std::all_of(bound.begin(), bound.end(), ::isdigit)) return std::nullopt;
        out.bound = std::stoull(bound);
    }
    return out;
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
        if (!seq) throw std::invalid_argument(path + ": cannot write type " + type);
        nlohmann::json items = v.is_null() ? nlohmann::json::array() : v;
        if (items.is_string()) {
            try {
                items = nlohmann::json::parse(items.get<std::string>());
            } catch (const std::exception&) {
                throw std::invalid_argument(path + ": '" + v.get<std::string>() + "' is not a JSON array");
            }
        }
        if (!items.is_array()) throw std::invalid_argument(path + ": " + v.dump() + " is not an array");
        if (seq->bound && items.size() > *seq->bound) throw std::invalid_argument(path + ": " + std::to_string(items.size()) + " items, at most " + std::to_string(*seq->bound));
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
        if (n >= e->second.size()) throw std::invalid_argument(path + ": " + v.dump() + " is no " + type);
        return w.put<uint32_t>(n);
    }
    auto s = structs_.find(type);
    if (s == structs_.end()) throw std::invalid_argument(path + ": unknown type " + type);
    if (!v.is_null() && !v.is_object()) throw std::invalid_argument(path + ": " + v.dump() + " is not a " + type);
    for (const auto& m : s->second) {
        const std::string p = path.empty() ? m.name : path + "." + m.name;
        const nlohmann::json& mv = v.is_object() && v.contains(m.name) ? v[m.name] : nlohmann::json();
        if (m.array) {
            nlohmann::json items = mv;
            if (items.is_string()) {
                try {
                    items = nlohmann::json::parse(items.get<std::string>());
                } catch (const std::exception&) {
                    throw std::invalid_argument(p + ": '" + mv.get<std::string>() + "' is not a JSON array");
                }
            }
            if (!items.is_null() && (!items.is_array() || items.size() != m.array))
                throw std::invalid_argument(p + ": expected " + std::to_string(m.array) + " items, got " + items.dump());
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
    if (!knows(type_name)) throw std::invalid_argument("unknown type " + type_name);
    CdrWriter w;
    write(type_name, sample, w, "");
    return w.bytes();
}

IdlDecoder::IdlDecoder(const std::string& dir)
{
    DIR* d = ::opendir(dir.c_str());
    if (!d) throw std::runtime_error("cannot read the IDL folder " + dir);
    std::vector<std::string> files;
    while (dirent* e = ::readdir(d)) {
        std::string name = e->d_name;
        if (name.size() > 4 && name.substr(name.size() - 4) == ".idl") files.push_back(dir + "/" + name);
    }
    ::closedir(d);
    for (const auto& f : files) {
        std::string text = read_text_file(f, "IDL file");
        parse(text, f);
        sources_[f.substr(dir.size() + 1)] = std::move(text);
    }
}

IdlDecoder::IdlDecoder(const std::map<std::string, std::string>& sources)
{
    for (const auto& [file, text] : sources) parse(text, file);
    sources_ = sources;
}

void IdlDecoder::parse(const std::string& text, const std::string& file)
{
    // Comments, preprocessor lines and annotations out; then every `struct NAME { ... };` and
    // `enum NAME { ... };` block read (modules, typedefs and the rest are passed over).
    const std::string clean = cleaned_idl(text, file);
    auto line_of = [&](size_t at) { return std::to_string(1 + std::count(clean.begin(), clean.begin() + long(at), '\n')); };
    auto word_at = [&](size_t& i) {
        const size_t from = i;
        while (i < clean.size() && is_word_char(clean[i])) ++i;
        return clean.substr(from, i - from);
    };
    auto skip_space = [&](size_t& i) {
        while (i < clean.size() && is_space(clean[i])) ++i;
    };
    for (size_t i = 0; i < clean.size();) {
        if (!is_word_char(clean[i])) {
            ++i;
            continue;
        }
        const std::string kind = word_at(i);
        if (kind != "struct" && kind != "enum") continue;
        size_t j = i;
        skip_space(j);
        const std::string name = word_at(j);
        skip_space(j);
        if (name.empty() || j >= clean.size() || clean[j] != '{') continue;  // a forward declaration, or no block
        const size_t open = j, close = clean.find('}', open);
        if (close == std::string::npos) throw std::runtime_error(file + ":" + line_of(open) + ": " + kind + " " + name + ": no closing }");
        size_t after = close + 1;
        skip_space(after);
        if (after >= clean.size() || clean[after] != ';') throw std::runtime_error(file + ":" + line_of(close) + ": " + kind + " " + name + ": expected ; after }");
        i = after + 1;
        const std::string body = clean.substr(open + 1, close - open - 1);
        if (kind == "enum") {
            std::vector<std::string> values;
            std::istringstream items(body);
            for (std::string v; std::getline(items, v, ',');) {
                v.erase(std::remove_if(v.begin(), v.end(), is_space), v.end());
                if (!v.empty()) values.push_back(v);
            }
            enums_[name] = values;
            continue;
        }
        std::vector<Member> members;
        for (size_t from = 0; from < body.size();) {
            size_t semi = body.find(';', from);
            if (semi == std::string::npos) semi = body.size();
            const std::string decl = body.substr(from, semi - from);
            const size_t decl_at = open + 1 + from + (decl.find_first_not_of(" \t\r\n") == std::string::npos ? 0 : decl.find_first_not_of(" \t\r\n"));
            from = semi + 1;
            std::string flat = trimmed(collapsed(decl));
            if (flat.empty()) continue;
            if (semi == body.size()) throw std::runtime_error(file + ":" + line_of(decl_at) + ": struct " + name + ": member '" + flat + "' has no ;");
            Member m;
            if (const auto key_at = flat.find(kKeyMark); key_at != std::string::npos) {
                m.key = true;
                flat = trimmed(collapsed(flat.erase(key_at, std::strlen(kKeyMark))));
            }
            auto bad = [&](const std::string& why) {
                return std::runtime_error(file + ":" + line_of(decl_at) + ": struct " + name + ": cannot read member '" + flat + "'" + why);
            };
            // TYPE NAME [ '[' N ']' ], TYPE one of: [unsigned] long long | long | short, sequence<...>, a word.
            size_t k = 0;
            auto next_word = [&] {
                while (k < flat.size() && flat[k] == ' ') ++k;
                const size_t w = k;
                while (k < flat.size() && is_word_char(flat[k])) ++k;
                return flat.substr(w, k - w);
            };
            std::string type = next_word();
            if (type == "sequence") {
                const size_t gt = flat.find('>', k);
                if (gt == std::string::npos) throw bad("");
                type = flat.substr(0, gt + 1);
                k = gt + 1;
                const auto seq = sequence_of(type);
                if (!seq) throw bad(": expected sequence<TYPE> or sequence<TYPE, BOUND>");
            } else if (type == "unsigned" || type == "long" || type == "short") {
                const size_t save = k;
                std::string second = next_word();
                if (type == "unsigned" && (second == "long" || second == "short")) {
                    type += " " + second;
                    const size_t save2 = k;
                    if (second == "long" && next_word() == "long") type += " long";
                    else k = save2;
                } else if (type == "long" && second == "long") {
                    type += " long";
                } else {
                    k = save;
                }
            }
            m.type = type;
            m.name = next_word();
            if (m.type.empty() || m.name.empty()) throw bad("");
            while (k < flat.size() && flat[k] == ' ') ++k;
            if (k < flat.size() && flat[k] == '[') {
                const size_t rb = flat.find(']', k);
                const std::string n = rb == std::string::npos ? "" : trimmed(flat.substr(k + 1, rb - k - 1));
                if (n.empty() || !std::all_of(n.begin(), n.end(), ::isdigit)) throw bad(": expected [N]");
                if (n.size() > 7 || std::stoul(n) == 0 || std::stoul(n) > 1'000'000) throw bad(": an array of 1..1000000 items");
                m.array = std::stoul(n);
                k = rb + 1;
            }
            while (k < flat.size() && flat[k] == ' ') ++k;
            if (k != flat.size()) throw bad("");
            members.push_back(m);
        }
        structs_[name] = members;
    }
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
        if (!seq) throw std::runtime_error("cannot read type " + type);
        const uint32_t n = c.get<uint32_t>();
        nlohmann::json out = nlohmann::json::array();
        if (seq->bound && n > *seq->bound) throw std::runtime_error("a sequence of " + std::to_string(n) + " items, at most " + std::to_string(*seq->bound));
        for (uint32_t i = 0; i < n; ++i) out.push_back(read(seq->element, c));
        return out;
    }
    if (auto e = enums_.find(type); e != enums_.end()) {
        const uint32_t v = c.get<uint32_t>();
        return v < e->second.size() ? nlohmann::json(e->second[v]) : nlohmann::json(v);
    }
    auto s = structs_.find(type);
    if (s == structs_.end()) throw std::runtime_error("unknown type " + type);
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
