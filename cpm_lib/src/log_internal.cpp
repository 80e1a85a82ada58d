#include "log_internal.hpp"

#include <cpm/get_time_ns.hpp>
#include <cpm/init.hpp>

#include <cstdio>

namespace cpm::detail {

void log_error(const std::string& message)
{
    std::fprintf(stderr, "[cpm error] %llu %s: %s\n", static_cast<unsigned long long>(get_time_ns()),
                 init_settings().node_id.c_str(), message.c_str());
}

}  // namespace cpm::detail
