#pragma once
#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

namespace cpm {

/// Reads a parameter from the lab's parameter server (topics `parameter`/`parameterRequest`).
/// Blocks until the value is known, at most `timeout`; then throws cpm::Error naming the
/// parameter. Also throws when the server still does not know the name after asking for a
/// second (a server still loading its file may answer "unknown" first), and when the parameter has
/// another type (naming both types). Values the server changes later reach later calls.
/// Thread-safe. Uses the default participant.
bool parameter_bool(const std::string& name, std::chrono::milliseconds timeout = std::chrono::seconds(5));
int32_t parameter_int(const std::string& name, std::chrono::milliseconds timeout = std::chrono::seconds(5));
uint64_t parameter_uint64_t(const std::string& name, std::chrono::milliseconds timeout = std::chrono::seconds(5));
double parameter_double(const std::string& name, std::chrono::milliseconds timeout = std::chrono::seconds(5));
std::string parameter_string(const std::string& name, std::chrono::milliseconds timeout = std::chrono::seconds(5));
std::vector<int32_t> parameter_ints(const std::string& name, std::chrono::milliseconds timeout = std::chrono::seconds(5));
std::vector<double> parameter_doubles(const std::string& name,
                                      std::chrono::milliseconds timeout = std::chrono::seconds(5));

}  // namespace cpm
