#pragma once
// A page filled from a template built into the library (a small part of Mustache's syntax):
//   {{key}}               the text of `key`, HTML-escaped: nothing from a run becomes markup
//   {{#key}}...{{/key}}   shown when the flag `key` is true, or once per item of the list `key`
//                         (an item's keys first, then the ones around it)
//   {{^key}}...{{/key}}   shown when the flag is false or the list empty
//   {{! ... }}            a comment, shown nowhere
// A section or comment tag alone on its line takes the line with it, so the template can put
// each on a line of its own.
#include <map>
#include <string>
#include <string_view>
#include <vector>

namespace cpm::lab::detail {

/// What fills a page: its texts, flags and lists by key.
struct PageValues
{
    std::map<std::string, std::string> text;
    std::map<std::string, bool> flags;
    std::map<std::string, std::vector<PageValues>> lists;
};

/// The page `page` filled with `values`. Throws cpm::Error naming a key that has no value or a
/// section that is not closed (a fault of the built-in template, which any rendering finds).
std::string fill(std::string_view page, const PageValues& values);

/// The text made safe to put between HTML tags and in attribute values.
std::string html_escape(std::string_view text);

/// lab_run/src/report_page.html, built into the library by lab_run/CMakeLists.txt.
extern const std::string_view kReportPage;

}  // namespace cpm::lab::detail
