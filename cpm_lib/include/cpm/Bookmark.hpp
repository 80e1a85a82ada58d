#pragma once
// Bookmarks: a moment of the lab marked with a text (cpm lab mark "car 3 touched the wall", the
// monitor's Mark button). Recorded by the history with everything else, listed by `cpm history
// marks`, drawn in the report's plots, exported as MCAP metadata (cpm.bookmark).
//
//   cpm::Participant p;
//   const auto m = cpm::mark(p, "lap 2 begins", "my_planner");  // throws when no history records it
#include <cpm/Participant.hpp>

#include <chrono>
#include <cstdint>
#include <string>

namespace cpm {

constexpr size_t kBookmarkTextMax = 256, kBookmarkSourceMax = 64;

/// What is wrong with a bookmark's text or source ("" when nothing): an empty text, a text or
/// source longer than its limit, a control character.
std::string bookmark_problem(const std::string& text, const std::string& source);

struct MarkResult
{
    uint64_t stamp_ns = 0;  ///< the moment marked (create_stamp)
    size_t readers = 0;     ///< the readers it reached (the history among them)
};

/// Publishes one Bookmark stamped now and waits until every reader matched within `wait` has
/// it. Throws cpm::Error naming the problem (bookmark_problem), or when no reader (no history
/// service, no lab run) matched within `wait`: a mark nobody records is lost.
MarkResult mark(Participant& participant, const std::string& text, const std::string& source,
                std::chrono::milliseconds wait = std::chrono::milliseconds(3000));

}  // namespace cpm
