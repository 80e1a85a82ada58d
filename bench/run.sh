#!/usr/bin/env bash
# ./lab bench: runs every benchmark; each prints its machine, settings, the cpm figures, the
# reference figures measured in the same run, and their ratio. One that fails or runs past its
# time (BENCH_TIMEOUT seconds, default 1200; then SIGTERM, SIGKILL 10 s later) is named, and the
# others still run; the exit status is 1 when any did.
set -uo pipefail
build="$1"; shift || true
bin="$build/bin"
limit="${BENCH_TIMEOUT:-1200}"
failed=()

# bench TITLE COMMAND...: one benchmark program, bounded in time.
bench() {
  local title="$1"; shift
  local name="${title%% (*}"
  echo "== $title"
  local status=0
  timeout -k 10 "$limit" "$@" || status=$?
  if [ "$status" = 124 ] || [ "$status" = 137 ]; then
    echo "bench: $name did not end within $limit s and was stopped; going on with the next" >&2
    failed+=("$name: did not end within $limit s")
  elif [ "$status" != 0 ]; then
    echo "bench: $name failed with exit status $status; going on with the next" >&2
    failed+=("$name: exit status $status")
  fi
  echo
}

bench "bench_latency (ping-pong, cpm vs raw Fast DDS vs Cyclone doing the same work and ddsperf)" "$bin/bench_latency" "$@"
bench "bench_throughput (1 KiB reliable, cpm vs raw Fast DDS vs Cyclone doing the same work, batched and not, and ddsperf)" "$bin/bench_throughput"
bench "bench_large (307 kB frames and 1 MiB: shared-memory transport, data sharing, written and read in place, vs Cyclone doing the same work)" "$bin/bench_large"
# Between hosts: two network namespaces joined by a veth pair (needs root).
if [ "$(id -u)" = 0 ]; then
  bench "across hosts (veth): bench_throughput" "$bin/bench_throughput" --link veth
  bench "across hosts (veth): bench_latency (100 B)" "$bin/bench_latency" --link veth --sizes 100 --count 4000
  bench "across hosts (veth): bench_large --camera (307 kB at 30 Hz)" "$bin/bench_large" --camera --link veth --seconds 30
  bench "bench_startup (a lab run across three hosts until every car is recorded, vs one host)" "$bin/bench_startup"
else
  echo "== across hosts (veth): not run, making network namespaces needs root"
  echo
fi
bench "bench_timer (tick jitter, cpm::Timer vs clock_nanosleep, normal and real time, idle and every core busy)" "$bin/bench_timer"
bench "bench_vehicle (simulated cars: bridge cycle cost, command latency, fleet capacity)" "$bin/bench_vehicle"
bench "bench_firmware (the car's AVR firmware in simavr: simulated MHz, real-time factor, chips per two cores, command latency vs firmware_sim, flash/RAM)" "$bin/bench_firmware"
bench "bench_fsm (state-machine tick cost; fsm_node command latency vs a plain DDS relay)" "$bin/bench_fsm"
bench "bench_history_store (the history store vs SQLite in memory, indexed, prepared statements)" "$bin/bench_history_store"
bench "bench_history_service (cpm_history: ingest without loss, query round trip vs plain ping-pong, memory)" "$bin/bench_history_service"
bench "bench_recording (recordings: ingest with --record on vs off, at from a recording vs live vs SQLite, size, replay timing)" "$bin/bench_recording"
bench "bench_aruco (perception: aruco_node vs plain OpenCV and AprilTag 3; detection, pose, latency, CameraFrame over DDS)" "$bin/bench_aruco"
bench "bench_ips (positioning: ips_node vs plain OpenCV per frame, 8 and 20 cars; accuracy; latency)" "$bin/bench_ips"
bench "bench_hlc (a user's controller: the list built, a step from list to answer, 20 cars)" "$bin/bench_hlc"
bench "bench_python (cpm from Python: one-way latency vs C++, a 100k-sample recording into columns vs C++)" \
  /usr/bin/python3 "$(dirname "$0")/python/bench_python.py" "$build"
bench "bench_routing (central routing: planning time per cycle, start-up, intersection throughput vs cpm_lab's scheme)" "$bin/bench_routing"
bench "bench_monitor (cpm monitor: create_stamp to a watcher's snapshot with 1 and 10 watchers, its CPU with 20 cars at 50 Hz)" "$bin/bench_monitor"

if [ ${#failed[@]} -gt 0 ]; then
  echo "bench: ${#failed[@]} program(s) did not finish:" >&2
  for f in "${failed[@]}"; do echo "  $f" >&2; done
  exit 1
fi
