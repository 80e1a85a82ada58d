#pragma once
// The history's words, spelled once: what a query found (Status), what a request asks (Kind)
// and which time it goes by (By). The same spellings are used on the wire (HistoryRequest.kind,
// HistoryReply.status), in `cpm history --json` and in C++:
//
//   status   ok | not_found | evicted | not_yet | timeout | gap | partial | unknown_object | error
//   kind     latest | at | older | younger | range | wait_next | successor | snapshot | info |
//            search | list | wait_object | changes
//   by       commit | data
#include <array>
#include <iosfwd>
#include <optional>
#include <string>
#include <string_view>
#include <utility>

namespace cpm::history {

enum class Status {
    ok,              ///< found (for a snapshot: every object's sample found)
    not_found,       ///< nothing at that time: before the first sample held, and nothing was evicted there
    evicted,         ///< it was held once and is older than the object's window now
    not_yet,         ///< after the newest sample held
    timeout,         ///< a waiting request's time ran out
    gap,             ///< successor: the next sample was evicted (or never arrived) before it was asked for
    partial,         ///< snapshot: some objects had a sample, some not (each sample carries its own status);
                     ///< range: part of the span was evicted, the samples are the part still held
    unknown_object,  ///< no object by that name or oid
    error,           ///< the request was malformed; the reply's error says why
};

enum class Kind {
    latest, at, older, younger, range, wait_next, successor, snapshot, info, search, list, wait_object, changes, save,
};

/// Which of a sample's two indexed times a query goes by.
enum class By { commit, data };

/// Each word with its spelling, in the order above: the one list the conversions and the
/// kAll* arrays are made from.
inline constexpr std::array<std::pair<Status, std::string_view>, 9> kStatusNames{{{Status::ok, "ok"},
                                                                                  {Status::not_found, "not_found"},
                                                                                  {Status::evicted, "evicted"},
                                                                                  {Status::not_yet, "not_yet"},
                                                                                  {Status::timeout, "timeout"},
                                                                                  {Status::gap, "gap"},
                                                                                  {Status::partial, "partial"},
                                                                                  {Status::unknown_object, "unknown_object"},
                                                                                  {Status::error, "error"}}};
inline constexpr std::array<std::pair<Kind, std::string_view>, 14> kKindNames{{{Kind::latest, "latest"},
                                                                               {Kind::at, "at"},
                                                                               {Kind::older, "older"},
                                                                               {Kind::younger, "younger"},
                                                                               {Kind::range, "range"},
                                                                               {Kind::wait_next, "wait_next"},
                                                                               {Kind::successor, "successor"},
                                                                               {Kind::snapshot, "snapshot"},
                                                                               {Kind::info, "info"},
                                                                               {Kind::search, "search"},
                                                                               {Kind::list, "list"},
                                                                               {Kind::wait_object, "wait_object"},
                                                                               {Kind::changes, "changes"},
                                                                               {Kind::save, "save"}}};

namespace detail {
template <class E, size_t N>
constexpr std::array<E, N> words_of(const std::array<std::pair<E, std::string_view>, N>& names)
{
    std::array<E, N> out{};
    for (size_t i = 0; i < N; ++i) out[i] = names[i].first;
    return out;
}
}  // namespace detail

inline constexpr auto kAllStatuses = detail::words_of(kStatusNames);
inline constexpr auto kAllKinds = detail::words_of(kKindNames);

std::string_view to_string(Status s);
std::string_view to_string(Kind k);
std::string_view to_string(By b);
std::optional<Status> status_from(std::string_view text);
std::optional<Kind> kind_from(std::string_view text);
/// "" is commit (the default on the wire).
std::optional<By> by_from(std::string_view text);
/// "latest, at, …": for messages that list what is known.
std::string known_kinds();

/// Whether a request of this kind may block for its timeout (the service answers those on
/// worker threads).
constexpr bool may_wait(Kind k) { return k == Kind::wait_next || k == Kind::successor || k == Kind::wait_object; }

std::ostream& operator<<(std::ostream& out, Status s);
std::ostream& operator<<(std::ostream& out, Kind k);

}  // namespace cpm::history
