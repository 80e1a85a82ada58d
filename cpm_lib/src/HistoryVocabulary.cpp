#include <cpm/HistoryVocabulary.hpp>

#include <ostream>

namespace cpm::history {

namespace {

template <class E, size_t N>
std::string_view name_of(const std::array<std::pair<E, std::string_view>, N>& names, E e, std::string_view otherwise)
{
    for (const auto& [word, name] : names) {
        if (word == e) return name;
    }
    return otherwise;
}

template <class E, size_t N>
std::optional<E> word_of(const std::array<std::pair<E, std::string_view>, N>& names, std::string_view text)
{
    for (const auto& [word, name] : names) {
        if (name == text) return word;
    }
    return std::nullopt;
}

}  // namespace

std::string_view to_string(Status s) { return name_of(kStatusNames, s, "error"); }

std::string_view to_string(Kind k) { return name_of(kKindNames, k, "?"); }

std::string_view to_string(By b) { return b == By::data ? "data" : "commit"; }

std::optional<Status> status_from(std::string_view text) { return word_of(kStatusNames, text); }

std::optional<Kind> kind_from(std::string_view text) { return word_of(kKindNames, text); }

std::optional<By> by_from(std::string_view text)
{
    if (text.empty() || text == "commit") return By::commit;
    if (text == "data") return By::data;
    return std::nullopt;
}

std::string known_kinds()
{
    std::string out;
    for (const auto& [kind, name] : kKindNames) (out += out.empty() ? "" : ", ") += name;
    return out;
}

std::ostream& operator<<(std::ostream& out, Status s) { return out << to_string(s); }

std::ostream& operator<<(std::ostream& out, Kind k) { return out << to_string(k); }

}  // namespace cpm::history
