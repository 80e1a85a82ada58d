#include "IdlParser.hpp"

#include <cpm/Error.hpp>

#include <algorithm>
#include <cctype>
#include <cstring>
#include <sstream>

namespace cpm::rtdb {

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
                throw Error(file + ":" + std::to_string(1 + std::count(text.begin(), text.begin() + long(i), '\n')) +
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

/// The word at k in a member's flat text, after spaces; k moves past it.
std::string next_word(const std::string& flat, size_t& k)
{
    while (k < flat.size() && flat[k] == ' ') ++k;
    const size_t w = k;
    while (k < flat.size() && is_word_char(flat[k])) ++k;
    return flat.substr(w, k - w);
}

/// The member's type at k: [unsigned] long long | long | short, sequence<...>, or a word; k
/// moves past it. `bad(why)` is the error to throw.
template <class Bad>
std::string type_at(const std::string& flat, size_t& k, const Bad& bad)
{
    std::string type = next_word(flat, k);
    if (type == "sequence") {
        const size_t gt = flat.find('>', k);
        if (gt == std::string::npos) throw bad("");
        type = flat.substr(0, gt + 1);
        k = gt + 1;
        if (!sequence_of(type)) throw bad(": expected sequence<TYPE> or sequence<TYPE, BOUND>");
    } else if (type == "unsigned" || type == "long" || type == "short") {
        const size_t save = k;
        const std::string second = next_word(flat, k);
        if (type == "unsigned" && (second == "long" || second == "short")) {
            type += " " + second;
            const size_t save2 = k;
            if (second == "long" && next_word(flat, k) == "long") type += " long";
            else k = save2;
        } else if (type == "long" && second == "long") {
            type += " long";
        } else {
            k = save;
        }
    }
    return type;
}

/// The items of an array suffix `[N]` at k (after spaces), 0 when there is none; k moves past it.
template <class Bad>
size_t array_items_at(const std::string& flat, size_t& k, const Bad& bad)
{
    while (k < flat.size() && flat[k] == ' ') ++k;
    if (k >= flat.size() || flat[k] != '[') return 0;
    const size_t rb = flat.find(']', k);
    const std::string n = rb == std::string::npos ? "" : trimmed(flat.substr(k + 1, rb - k - 1));
    if (n.empty() || !std::all_of(n.begin(), n.end(), ::isdigit)) throw bad(": expected [N]");
    if (n.size() > 7 || std::stoul(n) == 0 || std::stoul(n) > 1'000'000) throw bad(": an array of 1..1000000 items");
    k = rb + 1;
    return std::stoul(n);
}

std::vector<std::string> enum_values(const std::string& body)
{
    std::vector<std::string> values;
    std::istringstream items(body);
    for (std::string v; std::getline(items, v, ',');) {
        v.erase(std::remove_if(v.begin(), v.end(), is_space), v.end());
        if (!v.empty()) values.push_back(v);
    }
    return values;
}

}  // namespace

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

IdlParser::IdlParser(const std::string& text, std::string file) : file_(std::move(file)), clean_(cleaned_idl(text, file_)) {}

void IdlParser::read_into(Structs& structs, Enums& enums) const
{
    for (size_t i = 0; i < clean_.size();) {
        const auto block = block_at(i);
        if (!block) continue;
        if (block->kind == "enum") enums[block->name] = enum_values(block->body);
        else structs[block->name] = members_of(*block);
    }
}

std::optional<IdlParser::Block> IdlParser::block_at(size_t& i) const
{
    auto word_at = [&](size_t& at) {
        const size_t from = at;
        while (at < clean_.size() && is_word_char(clean_[at])) ++at;
        return clean_.substr(from, at - from);
    };
    auto skip_space = [&](size_t& at) {
        while (at < clean_.size() && is_space(clean_[at])) ++at;
    };
    if (!is_word_char(clean_[i])) {
        ++i;
        return std::nullopt;
    }
    Block b;
    b.kind = word_at(i);
    if (b.kind != "struct" && b.kind != "enum") return std::nullopt;
    size_t j = i;
    skip_space(j);
    b.name = word_at(j);
    skip_space(j);
    if (b.name.empty() || j >= clean_.size() || clean_[j] != '{') return std::nullopt;  // a forward declaration, or no block
    b.open = j;
    const size_t close = clean_.find('}', b.open);
    if (close == std::string::npos) throw Error(file_ + ":" + line_of(b.open) + ": " + b.kind + " " + b.name + ": no closing }");
    size_t after = close + 1;
    skip_space(after);
    if (after >= clean_.size() || clean_[after] != ';') {
        throw Error(file_ + ":" + line_of(close) + ": " + b.kind + " " + b.name + ": expected ; after }");
    }
    i = after + 1;
    b.body = clean_.substr(b.open + 1, close - b.open - 1);
    return b;
}

std::vector<IdlDecoder::Member> IdlParser::members_of(const Block& b) const
{
    std::vector<IdlDecoder::Member> members;
    const std::string& body = b.body;
    for (size_t from = 0; from < body.size();) {
        size_t semi = body.find(';', from);
        if (semi == std::string::npos) semi = body.size();
        const std::string decl = body.substr(from, semi - from);
        const size_t first = decl.find_first_not_of(" \t\r\n");
        const size_t decl_at = b.open + 1 + from + (first == std::string::npos ? 0 : first);
        from = semi + 1;
        const std::string flat = trimmed(collapsed(decl));
        if (flat.empty()) continue;
        if (semi == body.size()) throw Error(file_ + ":" + line_of(decl_at) + ": struct " + b.name + ": member '" + flat + "' has no ;");
        members.push_back(member(b, flat, decl_at));
    }
    return members;
}

IdlDecoder::Member IdlParser::member(const Block& b, std::string flat, size_t decl_at) const
{
    IdlDecoder::Member m;
    if (const auto key_at = flat.find(kKeyMark); key_at != std::string::npos) {
        m.key = true;
        flat = trimmed(collapsed(flat.erase(key_at, std::strlen(kKeyMark))));
    }
    auto bad = [&](const std::string& why) {
        return Error(file_ + ":" + line_of(decl_at) + ": struct " + b.name + ": cannot read member '" + flat + "'" + why);
    };
    size_t k = 0;
    m.type = type_at(flat, k, bad);
    m.name = next_word(flat, k);
    if (m.type.empty() || m.name.empty()) throw bad("");
    m.array = array_items_at(flat, k, bad);
    while (k < flat.size() && flat[k] == ' ') ++k;
    if (k != flat.size()) throw bad("");
    return m;
}

std::string IdlParser::line_of(size_t at) const { return std::to_string(1 + std::count(clean_.begin(), clean_.begin() + long(at), '\n')); }

}  // namespace cpm::rtdb
