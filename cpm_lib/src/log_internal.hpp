#pragma once
#include <string>

namespace cpm::detail {

/// Reports a problem that cannot be thrown (in a worker or DDS thread) on stderr, stamped
/// with the time and the node id.
void log_error(const std::string& message);

}  // namespace cpm::detail
