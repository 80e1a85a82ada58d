#!/usr/bin/env bash
# Installs this build of cpm into a temporary prefix, builds examples/installed_consumer
# against it with find_package(cpm), and runs it on this test's own domain.
set -euo pipefail
build="$1"; source_dir="$2"
source "$source_dir/tests/support/claim_domain.sh"
claim_test_domain
work=$(mktemp -d /tmp/cpm_install_test.XXXXXX)
trap 'rm -rf "$work"' EXIT

cmake --install "$build" --prefix "$work/prefix" > "$work/install.log"
cmake -S "$source_dir/examples/installed_consumer" -B "$work/consumer" -G Ninja \
      -DCMAKE_PREFIX_PATH="$work/prefix" > "$work/configure.log" || { cat "$work/configure.log"; exit 1; }
cmake --build "$work/consumer" > "$work/build.log" || { cat "$work/build.log"; exit 1; }
# Not from the build tree: the program must find the installed libraries on its own.
ldd "$work/consumer/installed_consumer" | grep -E "libcpm" | grep -q "$work/prefix" \
  || { echo "installed_consumer does not use the installed libcpm:"; ldd "$work/consumer/installed_consumer"; exit 1; }
"$work/consumer/installed_consumer"

# The README's first C++ example, exactly as printed there, builds against the installed package
# at the language level the README declares (C++20).
mkdir -p "$work/readme"
awk '/^```cpp$/ {inside = 1; next} inside && /^```$/ {exit} inside {print}' "$source_dir/README.md" > "$work/readme/main.cpp"
[ -s "$work/readme/main.cpp" ] || { echo "README.md has no C++ example"; exit 1; }
cat > "$work/readme/CMakeLists.txt" <<'CMAKE'
cmake_minimum_required(VERSION 3.16)
project(readme_example LANGUAGES CXX)
find_package(cpm REQUIRED)
add_executable(readme_example main.cpp)
target_compile_features(readme_example PRIVATE cxx_std_20)
target_link_libraries(readme_example PRIVATE cpm::cpm)
CMAKE
cmake -S "$work/readme" -B "$work/readme/build" -G Ninja -DCMAKE_PREFIX_PATH="$work/prefix" > "$work/readme.log" \
  && cmake --build "$work/readme/build" >> "$work/readme.log" || { echo "the README's example does not build:"; cat "$work/readme.log"; exit 1; }
"$work/readme/build/readme_example"

# The Cyclone DDS configuration the README points foreign programs at is installed.
[ -f "$work/prefix/share/cpm/cyclonedds-localhost.xml" ] || { echo "share/cpm/cyclonedds-localhost.xml is not installed"; exit 1; }
echo "installed: the consumer, the README's example and the Cyclone configuration"

# A program using Reader, Writer and HistoryClient reads no Fast DDS header (the generated types
# may read Fast CDR's): their type support is compiled into cpm::idl.
cat > "$work/light.cpp" <<'CPP'
#include <cpm/HistoryClient.hpp>
#include <cpm/Reader.hpp>
#include <cpm/Writer.hpp>
#include <VehicleState.h>
int main()
{
    cpm::Writer<VehicleState> writer("vehicleState");
    cpm::Reader<VehicleState> reader("vehicleState");
    cpm::HistoryClient history;
    (void)writer.write(reader.get_sample(0).sample);
    return history.latest<VehicleState>("vehicleState", 1).ok() ? 0 : 1;
}
CPP
g++ -std=c++17 -H -fsyntax-only -I"$work/prefix/include" -I"$work/prefix/include/cpm/idl" "$work/light.cpp" 2> "$work/headers.txt" \
  || { cat "$work/headers.txt"; exit 1; }
if grep -E "(fastdds|fastrtps)/" "$work/headers.txt"; then
  echo "a program using cpm's public headers reads the Fast DDS headers above"
  exit 1
fi
echo "light: $(grep -c '^\.' "$work/headers.txt") headers read, none of Fast DDS"
