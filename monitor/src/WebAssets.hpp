#pragma once
// The monitor's page, built into the library from monitor/web/ (embed_web.cmake writes the .cpp):
// nothing the page needs is fetched from anywhere but the monitor itself.
#include <string_view>
#include <vector>

namespace cpm::monitor {

struct WebAsset
{
    std::string_view path;          ///< as requested: "/index.html", "/monitor.js", …
    std::string_view content_type;
    std::string_view body;
};

const std::vector<WebAsset>& web_assets();

}  // namespace cpm::monitor
