#include <cpm/Bookmark.hpp>

#include <cpm/Error.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/stamp_message.hpp>
#include <cpm/topics.hpp>

#include <Bookmark.h>

#include <algorithm>

namespace cpm {

std::string bookmark_problem(const std::string& text, const std::string& source)
{
    if (text.find_first_not_of(" \t") == std::string::npos) return "a bookmark needs a text";
    if (text.size() > kBookmarkTextMax) return "the text is " + std::to_string(text.size()) + " bytes; at most " + std::to_string(kBookmarkTextMax);
    if (source.size() > kBookmarkSourceMax) {
        return "the source is " + std::to_string(source.size()) + " bytes; at most " + std::to_string(kBookmarkSourceMax);
    }
    auto control = [](const std::string& s) { return std::any_of(s.begin(), s.end(), [](char c) { return static_cast<unsigned char>(c) < 0x20; }); };
    if (control(text) || control(source)) return "a control character (a line break, a tab) in the text or source";
    return "";
}

MarkResult mark(Participant& participant, const std::string& text, const std::string& source, std::chrono::milliseconds wait)
{
    if (const std::string problem = bookmark_problem(text, source); !problem.empty()) throw Error("bookmark: " + problem);
    Writer<Bookmark> writer(participant, topics::bookmark.name, topics::bookmark.writer);
    if (!writer.wait_for_matched(1, wait)) {
        throw Error("bookmark: nobody records bookmarks on this domain (no history service, no lab run); the mark is not made");
    }
    Bookmark b;
    b.text(text);
    b.source(source);
    const uint64_t now = get_time_ns();
    stamp_message(b, now, 0);
    if (!writer.write(b) || !writer.wait_for_acknowledgments(wait)) throw Error("bookmark: it was not delivered within " + std::to_string(wait.count()) + " ms");
    return {now, writer.matched_subscriptions()};
}

}  // namespace cpm
