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

# Every exported target links from an outside project: one small program each, which includes
# its public header and calls into its library, so that the package declares every public
# dependency (a missing find_dependency fails here at configure time).
mkdir -p "$work/each"
each() {  # TARGET HEADER STATEMENT
  cat > "$work/each/$1.cpp" <<CPP
#include <$2>
int main(int argc, char**) { if (argc > 5) { $3; } return 0; }
CPP
  echo "add_executable(use_$1 $1.cpp)" >> "$work/each/CMakeLists.txt"
  echo "target_link_libraries(use_$1 PRIVATE cpm::$1)" >> "$work/each/CMakeLists.txt"
}
cat > "$work/each/CMakeLists.txt" <<'CMAKE'
cmake_minimum_required(VERSION 3.16)
project(each_target LANGUAGES CXX)
set(CMAKE_CXX_STANDARD 20)
find_package(cpm REQUIRED)
CMAKE
each idl VehicleState.h 'VehicleState s; return s.vehicle_id()'
each cpm cpm/get_time_ns.hpp 'return int(cpm::get_time_ns() % 2)'
each rtdb cpm/rtdb/Recording.hpp 'return int(cpm::rtdb::load_recording("x").samples)'
each lab cpm/lab/Scenario.hpp 'return int(cpm::lab::load_scenario("x").vehicles.size())'
each monitor cpm/monitor/Monitor.hpp 'return int(cpm::monitor::listen_problem("127.0.0.1", 1).size())'
each vehicle cpm/vehicle/World.hpp 'return int(cpm::vehicle::World::load("x").walls().size())'
each vehicle_hil cpm/vehicle/FirmwareHil.hpp 'return int(cpm::vehicle::default_firmware_elf().size() + cpm::vehicle::crc16(nullptr, 0))'
each aruco cpm/aruco/Camera.hpp 'return int(cpm::aruco::Camera::load("x").width)'
each aruco_node cpm/aruco/ArucoNode.hpp 'std::string why; return int(cpm::aruco::frame_image(CameraFrame{}, cpm::aruco::Camera{}, why).cols)'
each fsm cpm/fsm/Loader.hpp 'return int(cpm::fsm::load_file("x").errors.size())'
each fsm_node cpm/fsm/FsmNode.hpp 'return int(cpm::fsm::inputs_from(VehicleState{}, RangeSensors{}, nullptr, 0).t)'
each routing cpm/routing/Conflicts.hpp 'return int(cpm::routing::footprint_distance({}, {}, {}))'
each hlc cpm/hlc/Middleware.hpp 'return int(cpm::hlc::to_string(cpm::hlc::Refusal::bad_value)[0])'
each routing_node cpm/routing/RoutingNode.hpp 'cpm::routing::RoutingNode node(cpm::routing::LaneGraph{}, {}); return 0'
targets=$(grep -c '^add_executable' "$work/each/CMakeLists.txt")
exported=$(grep -c '^add_library(cpm::' "$work/prefix/lib/cmake/cpm/cpmTargets.cmake")
[ "$targets" -eq "$exported" ] || { echo "$exported targets are exported, $targets tried here: add the new one"; exit 1; }
cmake -S "$work/each" -B "$work/each/build" -G Ninja -DCMAKE_PREFIX_PATH="$work/prefix" > "$work/each.log" 2>&1 \
  && cmake --build "$work/each/build" >> "$work/each.log" 2>&1 || { echo "an exported target does not link from outside:"; cat "$work/each.log"; exit 1; }
echo "every exported target ($targets) builds into a program outside this tree"

# Python finds the installed package under the prefix, its module the installed libraries.
out=$(PYTHONPATH="$work/prefix/lib/python3/dist-packages" /usr/bin/python3 -c "
import cpm, cpm.types
s = cpm.types.VehicleState(vehicle_id=7, speed=1.25)
assert cpm.types.VehicleState.from_dict(s.to_dict()) == s
print(cpm.__file__)") || { echo "the installed Python package does not import"; exit 1; }
case "$out" in "$work/prefix/"*) ;; *) echo "python imported cpm from $out, not from the prefix"; exit 1 ;; esac
ldd "$work/prefix/lib/python3/dist-packages/cpm/"_cpm*.so | grep libcpm | grep -q "$work/prefix" \
  || { echo "the installed Python module does not use the installed libcpm:"; ldd "$work/prefix/lib/python3/dist-packages/cpm/"_cpm*.so; exit 1; }
echo "python: import cpm from the prefix"
