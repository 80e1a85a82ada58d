#pragma once
// cpm's fuzz targets: each one takes arbitrary bytes to one of cpm's parsers, the way a file, a
// serial line, a request or a command line hands them over. A target returns normally for any
// input that the parser answers the documented way (a value, or the documented error with its
// message); anything else (a crash, a sanitizer finding, an undocumented exception escaping,
// a broken round trip) is a finding.
//
// The same target source is built two ways (fuzz/CMakeLists.txt):
// - CPM_FUZZ=ON (clang): one libFuzzer executable per target, fuzz_<name>;
// - every normal build: all targets in cpm_fuzz_replay, which runs the checked-in corpus
//   (fuzz/corpus/<name>/) as a ctest, so that every case ever found stays fixed.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace cpm::fuzz {

using Target = int (*)(const uint8_t* data, size_t size);

/// Registers a target under its name (done by CPM_FUZZ_TARGET).
bool add_target(const char* name, Target target);
/// The registered targets, by name.
const std::vector<std::pair<std::string, Target>>& targets();

/// The bytes as text.
inline std::string text(const uint8_t* data, size_t size) { return std::string(reinterpret_cast<const char*>(data), size); }

/// A file holding these bytes, for parsers that read only files: one per process and name
/// (overwritten on every call) in a folder of this process's own, removed at exit.
std::string scratch_file(const std::string& name, const uint8_t* data, size_t size);

/// Aborts with the message (a finding) when `ok` is false: for properties a target checks.
void expect(bool ok, const char* what);

}  // namespace cpm::fuzz

/// Defines the fuzz target `name`: CPM_FUZZ_TARGET(world) { ... use data, size ...; return 0; }
#define CPM_FUZZ_TARGET(name)                                                                     \
    static int cpm_fuzz_target_##name(const uint8_t* data, size_t size);                          \
    [[maybe_unused]] static const bool cpm_fuzz_registered_##name =                               \
        ::cpm::fuzz::add_target(#name, cpm_fuzz_target_##name);                                   \
    static int cpm_fuzz_target_##name([[maybe_unused]] const uint8_t* data, [[maybe_unused]] size_t size)
