#include "IdlDecoder.hpp"

#include <cstring>
#include <dirent.h>
#include <fstream>
#include <regex>
#include <sstream>
#include <stdexcept>

namespace cpm::tools {

/// Reads plain CDR: each primitive aligned to its size from the start of the data (after the
/// 4-byte encapsulation header), in the encapsulation's byte order.
class CdrCursor
{
public:
    explicit CdrCursor(const std::vector<uint8_t>& b) : b_(b), little_(b.size() >= 2 && (b[1] & 1)) {}
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
        std::string s(reinterpret_cast<const char*>(b_.data() + at_), n ? n - 1 : 0);
        at_ += n;
        return s;
    }
    bool ok() const { return b_.size() >= 4; }

private:
    void align(size_t n) { at_ = 4 + (at_ - 4 + n - 1) / n * n; }
    void need(size_t n)
    {
        if (at_ + n > b_.size()) throw std::out_of_range("payload ends early");
    }
    const std::vector<uint8_t>& b_;
    bool little_;
    size_t at_ = 4;
};

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
        std::ifstream in(f);
        std::stringstream text;
        text << in.rdbuf();
        parse(text.str(), f);
    }
}

void IdlDecoder::parse(const std::string& text, const std::string& file)
{
    // Drop comments, preprocessor lines and annotations; then read enum and struct blocks.
    std::string clean;
    std::istringstream lines(text);
    for (std::string line; std::getline(lines, line);) {
        if (auto c = line.find("//"); c != std::string::npos) line.erase(c);
        auto first = line.find_first_not_of(" \t");
        if (first != std::string::npos && line[first] == '#') continue;
        clean += line + "\n";
    }
    clean = std::regex_replace(clean, std::regex(R"(/\*[\s\S]*?\*/)"), " ");
    clean = std::regex_replace(clean, std::regex(R"(@\w+(\([^)]*\))?)"), " ");
    static const std::regex block(R"((struct|enum)\s+(\w+)\s*\{([^}]*)\}\s*;)");
    static const std::regex member(R"(^\s*((?:unsigned\s+)?(?:long\s+long|long|short)|sequence\s*<[^>]*>|\w+)\s+(\w+)\s*(?:\[\s*(\d+)\s*\])?\s*$)");
    for (std::sregex_iterator it(clean.begin(), clean.end(), block), end; it != end; ++it) {
        const std::string kind = (*it)[1], name = (*it)[2], body = (*it)[3];
        if (kind == "enum") {
            std::vector<std::string> values;
            std::istringstream items(body);
            for (std::string v; std::getline(items, v, ',');) {
                v = std::regex_replace(v, std::regex(R"(\s+)"), "");
                if (!v.empty()) values.push_back(v);
            }
            enums_[name] = values;
            continue;
        }
        std::vector<Member> members;
        std::istringstream decls(body);
        for (std::string decl; std::getline(decls, decl, ';');) {
            if (decl.find_first_not_of(" \t\n") == std::string::npos) continue;
            std::smatch m;
            const std::string flat = std::regex_replace(decl, std::regex(R"(\s+)"), " ");
            if (!std::regex_match(flat, m, member)) throw std::runtime_error(file + ": struct " + name + ": cannot read member '" + flat + "'");
            Member mem{m[2], std::regex_replace(std::string(m[1]), std::regex(R"(\s+)"), " "), m[3].matched ? std::stoul(m[3]) : 0};
            members.push_back(mem);
        }
        structs_[name] = members;
    }
}

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
    if (type == "string") return c.string();
    if (type.rfind("sequence", 0) == 0) {
        std::smatch m;
        static const std::regex seq(R"(sequence\s*<\s*([^,>]+?)\s*(?:,\s*\d+\s*)?>)");
        if (!std::regex_match(type, m, seq)) throw std::runtime_error("cannot read type " + type);
        const uint32_t n = c.get<uint32_t>();
        nlohmann::json out = nlohmann::json::array();
        for (uint32_t i = 0; i < n; ++i) out.push_back(read(m[1], c));
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
    if (!knows(type_name)) return std::nullopt;
    CdrCursor c(payload);
    if (!c.ok()) return std::nullopt;
    try {
        return read(type_name, c);
    } catch (const std::exception&) {
        return std::nullopt;
    }
}

}  // namespace cpm::tools
