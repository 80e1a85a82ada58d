#pragma once
#include <string>

namespace cpm {

/// The whole content of a text file. Throws cpm::Error naming the path, `what` it should be
/// (e.g. "map file") and why it cannot be read: "no such file", "permission denied", "it is a
/// directory", or the system's reason.
std::string read_text_file(const std::string& path, const std::string& what);

}  // namespace cpm
