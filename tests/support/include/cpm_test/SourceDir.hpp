#pragma once
#include <string>

namespace cpm_test {

/// cpm's source folder (scenarios/, share/, examples/), as CMake configured the tests. A function
/// of the support library, not a definition in every test: a test's object then holds no path of
/// its checkout, and ccache gives it to another clone of the same commit.
std::string source_dir();

}  // namespace cpm_test
