#!/usr/bin/env bash
# ./lab bench: runs every benchmark; each prints its machine, settings, the cpm figures, the
# reference figures measured in the same run, and their ratio.
set -euo pipefail
build="$1"; shift || true
bin="$build/bin"
echo "== bench_latency (ping-pong, cpm vs raw Fast DDS vs Cyclone doing the same work and ddsperf)"
"$bin/bench_latency" "$@"
echo
echo "== bench_throughput (1 KiB reliable, cpm vs raw Fast DDS vs Cyclone doing the same work, batched and not, and ddsperf)"
"$bin/bench_throughput"
echo
echo "== bench_large (307 kB frames and 1 MiB: shared-memory transport, data sharing, written and read in place, vs Cyclone doing the same work)"
"$bin/bench_large"
echo
# Between hosts: two network namespaces joined by a veth pair (needs root).
if [ "$(id -u)" = 0 ]; then
  echo "== across hosts (veth): bench_throughput, bench_latency (100 B), bench_large --camera (307 kB at 30 Hz)"
  "$bin/bench_throughput" --link veth
  "$bin/bench_latency" --link veth --sizes 100 --count 4000
  "$bin/bench_large" --camera --link veth --seconds 30
  echo "== bench_startup (a lab run across three hosts until every car is recorded, vs one host)"
  "$bin/bench_startup"
else
  echo "== across hosts (veth): not run, making network namespaces needs root"
fi
echo
echo "== bench_timer (tick jitter, cpm::Timer vs clock_nanosleep)"
"$bin/bench_timer"
echo
echo "== bench_vehicle (simulated cars: bridge cycle cost, command latency, fleet capacity)"
"$bin/bench_vehicle"
echo
echo "== bench_fsm (state-machine tick cost; fsm_node command latency vs a plain DDS relay)"
"$bin/bench_fsm"
echo
echo "== bench_history_store (the history store vs SQLite in memory, indexed, prepared statements)"
"$bin/bench_history_store"
echo
echo "== bench_history_service (cpm_history: ingest without loss, query round trip vs plain ping-pong, memory)"
"$bin/bench_history_service"
echo
echo "== bench_recording (recordings: ingest with --record on vs off, at from a recording vs live vs SQLite, size, replay timing)"
"$bin/bench_recording"
echo
echo "== bench_aruco (perception: aruco_node vs plain OpenCV and AprilTag 3; detection, pose, latency, CameraFrame over DDS)"
"$bin/bench_aruco"
echo
echo "== bench_hlc (a user's controller: the list built, a step from list to answer, 20 cars)"
"$bin/bench_hlc"
echo
echo "== bench_python (cpm from Python: one-way latency vs C++, a 100k-sample recording into columns vs C++)"
/usr/bin/python3 "$(dirname "$0")/python/bench_python.py" "$build"
echo
echo "== bench_routing (central routing: planning time per cycle, start-up, intersection throughput vs cpm_lab's scheme)"
"$bin/bench_routing"
echo
echo "== bench_monitor (cpm monitor: create_stamp to a watcher's snapshot with 1 and 10 watchers, its CPU with 20 cars at 50 Hz)"
"$bin/bench_monitor"
