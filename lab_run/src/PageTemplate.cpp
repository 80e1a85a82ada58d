#include "PageTemplate.hpp"

#include <cpm/Error.hpp>

namespace cpm::lab::detail {

namespace {

/// A tag of a page template: what it says, and where it stands (its whole line, when it is a
/// section, close or comment tag alone on that line).
struct PageTag
{
    enum class Kind { none, text, section, inverted, close, comment };
    Kind kind = Kind::none;
    std::string key;
    size_t begin = 0, end = 0;
};

/// The scopes a key is looked up in, the innermost (a list's item) last.
using PageScopes = std::vector<const PageValues*>;

void take_line(std::string_view page, PageTag& tag)
{
    size_t begin = tag.begin, end = tag.end;
    while (begin > 0 && (page[begin - 1] == ' ' || page[begin - 1] == '\t')) --begin;
    while (end < page.size() && (page[end] == ' ' || page[end] == '\t')) ++end;
    if ((begin == 0 || page[begin - 1] == '\n') && (end == page.size() || page[end] == '\n')) {
        tag.begin = begin;
        tag.end = end == page.size() ? end : end + 1;
    }
}

/// The first tag in page[from, to); one of kind none when there is none.
PageTag next_tag(std::string_view page, size_t from, size_t to)
{
    const size_t open = page.find("{{", from);
    if (open == std::string_view::npos || open >= to) return {};
    const size_t close = page.find("}}", open + 2);
    if (close == std::string_view::npos || close + 2 > to) {
        throw Error("report page template: the tag at offset " + std::to_string(open) + " is not closed");
    }
    PageTag tag{.begin = open, .end = close + 2};
    std::string_view inside = page.substr(open + 2, close - open - 2);
    const char sigil = inside.empty() ? ' ' : inside.front();
    using K = PageTag::Kind;
    tag.kind = sigil == '#' ? K::section : sigil == '^' ? K::inverted : sigil == '/' ? K::close : sigil == '!' ? K::comment : K::text;
    if (tag.kind != K::text) inside.remove_prefix(1);
    while (!inside.empty() && inside.front() == ' ') inside.remove_prefix(1);
    while (!inside.empty() && inside.back() == ' ') inside.remove_suffix(1);
    tag.key = std::string(inside);
    if (tag.kind != K::text) take_line(page, tag);
    return tag;
}

/// The tag closing the section `open`, before `to`.
PageTag close_of(std::string_view page, const PageTag& open, size_t to)
{
    int depth = 0;
    for (PageTag t = next_tag(page, open.end, to); t.kind != PageTag::Kind::none; t = next_tag(page, t.end, to)) {
        if (t.key != open.key) continue;
        if (t.kind == PageTag::Kind::section || t.kind == PageTag::Kind::inverted) ++depth;
        if (t.kind == PageTag::Kind::close && depth-- == 0) return t;
    }
    throw Error("report page template: the section '" + open.key + "' is not closed");
}

template <class T>
const T* find(const PageScopes& scopes, std::map<std::string, T> PageValues::*member, const std::string& key)
{
    for (auto s = scopes.rbegin(); s != scopes.rend(); ++s) {
        const auto& values = (*s)->*member;
        if (const auto it = values.find(key); it != values.end()) return &it->second;
    }
    return nullptr;
}

void fill_range(std::string_view page, size_t from, size_t to, PageScopes& scopes, std::string& out);

/// The section between `open` and `close`: once per list item, or once or not at all.
void fill_section(std::string_view page, const PageTag& open, const PageTag& close, PageScopes& scopes, std::string& out)
{
    const bool shown_when_true = open.kind == PageTag::Kind::section;
    if (const auto* list = find(scopes, &PageValues::lists, open.key)) {
        if (!shown_when_true) {
            if (list->empty()) fill_range(page, open.end, close.begin, scopes, out);
            return;
        }
        for (const auto& item : *list) {
            scopes.push_back(&item);
            fill_range(page, open.end, close.begin, scopes, out);
            scopes.pop_back();
        }
        return;
    }
    const bool* flag = find(scopes, &PageValues::flags, open.key);
    if (!flag) throw Error("report page template: no flag or list '" + open.key + "'");
    if (*flag == shown_when_true) fill_range(page, open.end, close.begin, scopes, out);
}

void fill_range(std::string_view page, size_t from, size_t to, PageScopes& scopes, std::string& out)
{
    size_t at = from;
    for (PageTag tag = next_tag(page, at, to); tag.kind != PageTag::Kind::none; tag = next_tag(page, at, to)) {
        out.append(page.substr(at, tag.begin - at));
        at = tag.end;
        switch (tag.kind) {
        case PageTag::Kind::text: {
            const std::string* text = find(scopes, &PageValues::text, tag.key);
            if (!text) throw Error("report page template: no text '" + tag.key + "'");
            out += html_escape(*text);
            break;
        }
        case PageTag::Kind::section:
        case PageTag::Kind::inverted: {
            const PageTag close = close_of(page, tag, to);
            fill_section(page, tag, close, scopes, out);
            at = close.end;
            break;
        }
        case PageTag::Kind::close: throw Error("report page template: '" + tag.key + "' closes no section");
        case PageTag::Kind::comment:
        case PageTag::Kind::none: break;
        }
    }
    out.append(page.substr(at, to - at));
}

}  // namespace

std::string html_escape(std::string_view text)
{
    std::string out;
    for (char c : text) {
        if (c == '<') out += "&lt;";
        else if (c == '>') out += "&gt;";
        else if (c == '&') out += "&amp;";
        else if (c == '"') out += "&quot;";
        else out += c;
    }
    return out;
}

std::string fill(std::string_view page, const PageValues& values)
{
    PageScopes scopes{&values};
    std::string out;
    fill_range(page, 0, page.size(), scopes, out);
    return out;
}

}  // namespace cpm::lab::detail
