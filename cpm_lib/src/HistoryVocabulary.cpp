#include <cpm/HistoryVocabulary.hpp>

#include <ostream>

namespace cpm::history {

std::string_view to_string(Status s)
{
    switch (s) {
    case Status::ok: return "ok";
    case Status::not_found: return "not_found";
    case Status::evicted: return "evicted";
    case Status::not_yet: return "not_yet";
    case Status::timeout: return "timeout";
    case Status::gap: return "gap";
    case Status::partial: return "partial";
    case Status::unknown_object: return "unknown_object";
    case Status::error: return "error";
    }
    return "error";
}

std::string_view to_string(Kind k)
{
    switch (k) {
    case Kind::latest: return "latest";
    case Kind::at: return "at";
    case Kind::older: return "older";
    case Kind::younger: return "younger";
    case Kind::range: return "range";
    case Kind::wait_next: return "wait_next";
    case Kind::successor: return "successor";
    case Kind::snapshot: return "snapshot";
    case Kind::info: return "info";
    case Kind::search: return "search";
    case Kind::list: return "list";
    case Kind::wait_object: return "wait_object";
    case Kind::changes: return "changes";
    }
    return "?";
}

std::string_view to_string(By b) { return b == By::data ? "data" : "commit"; }

namespace {

template <class E, size_t N>
std::optional<E> find_spelling(const std::array<E, N>& all, std::string_view text)
{
    for (E e : all) {
        if (to_string(e) == text) return e;
    }
    return std::nullopt;
}

}  // namespace

std::optional<Status> status_from(std::string_view text) { return find_spelling(kAllStatuses, text); }

std::optional<Kind> kind_from(std::string_view text) { return find_spelling(kAllKinds, text); }

std::optional<By> by_from(std::string_view text)
{
    if (text.empty() || text == "commit") return By::commit;
    if (text == "data") return By::data;
    return std::nullopt;
}

std::string known_kinds()
{
    std::string out;
    for (Kind k : kAllKinds) (out += out.empty() ? "" : ", ") += to_string(k);
    return out;
}

std::ostream& operator<<(std::ostream& out, Status s) { return out << to_string(s); }

std::ostream& operator<<(std::ostream& out, Kind k) { return out << to_string(k); }

}  // namespace cpm::history
