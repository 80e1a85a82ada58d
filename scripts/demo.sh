#!/usr/bin/env bash
# ./lab demo, part 1: a writer publishes 4 simulated vehicles' VehicleState at 50 Hz (valid
# 60 ms after creation); a monitor reads them with one MultiVehicleReader and prints each
# vehicle's newest valid state and its age once a second. Both stop by themselves after ~5 s.
# Part 2: the closed loop: a simulated car (firmware_sim + vehicle_bridge over a pty) in the
# corridor, driven by fsm_node; it prints each transition and a short report. cpm_history
# records the run; the demo ends by asking it what happened.
# Part 3: a car with a camera drives through ArUco gates. Part 4: eight cars under
# central_routing on the lab road map; `cpm routing watch` judges them by their true poses.
set -euo pipefail
build="$1"; shift || true
bin="$build/bin"
export CPM_DOMAIN_ID="${CPM_DOMAIN_ID:-0}"
vehicles=4
seconds=5

echo "demo: domain $CPM_DOMAIN_ID, this host only (loopback + shared memory); $vehicles vehicles, ${seconds} s"
"$bin/vehicle_state_monitor" --vehicles $vehicles --seconds $seconds &
monitor=$!
"$bin/vehicle_state_writer" --vehicles $vehicles --seconds $((seconds + 1)) &
writer=$!
trap 'kill $monitor $writer 2>/dev/null || true' EXIT INT TERM

status=0
wait $monitor || status=$?
wait $writer || status=$?
echo
if [ $status -ne 0 ]; then
  echo "demo: FAILED (exit $status)" >&2
  exit $status
fi
echo "demo: the monitor saw every vehicle's newest valid state. Each sample becomes valid 60 ms"
echo "      after it was created, so 'since created' is 60..80 ms and the age (time since it became"
echo "      valid) stays within one 20 ms period: newer samples exist but are not valid yet."

# Part 2: the closed loop. A simulated car (firmware simulator + bridge over a pseudo-terminal)
# in the corridor, driven by fsm_node running scenarios/fsm/corridor.json.
echo
root="$(cd "$(dirname "$0")/.." && pwd)"
echo "demo: simulated car 5 in scenarios/maps/corridor.json, driven by fsm_node with scenarios/fsm/corridor.json"
"$bin/cpm" fsm check "$root/scenarios/fsm/corridor.json"
"$bin/cpm_history" --window 60s > /tmp/cpm_demo_history.$$.out 2>&1 &
history=$!
"$bin/cpm" vehicle sim --id 5 --map "$root/scenarios/maps/corridor.json" --start 0,-0.01,0 > /tmp/cpm_demo_sim.$$.out 2>&1 &
sim=$!
trap 'kill $monitor $writer $sim $history 2>/dev/null || true' EXIT INT TERM
timeout 60 "$bin/fsm_node" --vehicle_id 5 --fsm "$root/scenarios/fsm/corridor.json" --report 2>/dev/null || status=$?
kill -INT $sim 2>/dev/null || true
wait $sim 2>/dev/null || true
echo
if [ $status -eq 0 ]; then
  echo "demo: the car followed the right wall at 0.50 m (past the door niche, whose jump FollowWall"
  echo "      ignores), turned left at the corner when the end wall came within 0.9 m, followed"
  echo "      the new right wall and stopped 0.6 m before the corridor's end. Draw the machine with"
  echo "      'build/bin/cpm fsm render scenarios/fsm/corridor.json -o corridor.svg'."
  echo
  echo "demo: what cpm_history recorded (cpm dump):"
  "$bin/cpm" dump || status=$?
  echo
  echo "demo: the car's state machine 3 s ago and the car's state then (cpm history at ... --time -3s):"
  "$bin/cpm" history at --topic fsmStatus --key 5 --time -3s || status=$?
  "$bin/cpm" history at --topic vehicleState --key 5 --time -3s || status=$?
  echo
  echo "      The demo stops its cpm_history now. To ask more, run one yourself: 'build/bin/cpm_history &'"
  echo "      keeps the last 10 s of every topic (--window 60s for more), then cpm history list |"
  echo "      search --name Range | range --topic rangeSensors --key 5 --from -5s --to -4s --json |"
  echo "      wait --topic vehicleState --key 5 ('cpm history --help' lists them all)."
else
  echo "demo: the closed loop FAILED (exit $status); the car's log: /tmp/cpm_demo_sim.$$.out" >&2
fi
kill -INT $history 2>/dev/null || true
wait $history 2>/dev/null || true
rm -f /tmp/cpm_demo_sim.$$.out /tmp/cpm_demo_history.$$.out
[ $status -eq 0 ] || exit $status

# Part 3: the gate course.
echo
gates="$root/scenarios/maps/gates.json"
camera="$root/scenarios/cameras/sim_640x480.yaml"
frame="${CPM_DEMO_FRAME:-$build/cpm_demo_camera.png}"
echo "demo: simulated car 6 with a camera in scenarios/maps/gates.json; aruco_node finds the markers,"
echo "      fsm_node drives scenarios/fsm/gates.json through the three gates"
"$bin/cpm" vehicle sim --id 6 --map "$gates" --camera "$camera" --start 0,0,0.3 > /tmp/cpm_demo_sim.$$.out 2>&1 &
sim=$!
"$bin/aruco_node" --vehicle_id 6 --camera "$camera" --world "$gates" > /tmp/cpm_demo_aruco.$$.out 2>&1 &
aruco=$!
"$bin/cpm" aruco gates --map "$gates" --id 6 --timeout 90s --frame-out "$frame" &
watcher=$!
trap 'kill $sim $aruco $watcher 2>/dev/null || true' EXIT INT TERM
timeout 90 "$bin/fsm_node" --vehicle_id 6 --fsm "$root/scenarios/fsm/gates.json" > /tmp/cpm_demo_fsm.$$.out 2>&1 || status=$?
wait $watcher || status=$?
kill -INT $aruco $sim 2>/dev/null || true
wait $aruco $sim 2>/dev/null || true
echo
if [ $status -eq 0 ]; then
  echo "demo: the car passed every gate. aruco_node: $(tail -n 1 /tmp/cpm_demo_aruco.$$.out)"
  echo "      The camera's view 2 m before the first gate: $frame"
  echo "      Render any view yourself: build/bin/cpm camera render --world scenarios/maps/gates.json"
  echo "      --camera scenarios/cameras/sim_640x480.yaml --pose 1,0.1,0.2 --out view.png"
else
  echo "demo: the gate course FAILED (exit $status); fsm_node said:" >&2
  cat /tmp/cpm_demo_fsm.$$.out >&2
fi
rm -f /tmp/cpm_demo_sim.$$.out /tmp/cpm_demo_aruco.$$.out /tmp/cpm_demo_fsm.$$.out
[ $status -eq 0 ] || exit $status

# Part 4: eight cars under central routing.
echo
lanes="$root/scenarios/lanes/intersection.json"
picture="${CPM_DEMO_ROUTING_PICTURE:-$build/cpm_demo_routing.png}"
routing_seconds="${CPM_DEMO_ROUTING_SECONDS:-120}"
echo "demo: eight simulated cars on scenarios/lanes/intersection.json (a two-lane ring, a cross through"
echo "      the middle, lane changes); central_routing plans all of them every 400 ms, ${routing_seconds} s of"
echo "      simulated time: cpm lab clock steps the cars, their bridge and the planner tick by tick, as fast"
echo "      as this machine computes (all eight cars in one simulator and one bridge process)"
"$bin/cpm" vehicle sim --id 1 --count 8 --lanes "$lanes" --simulated_time > /tmp/cpm_demo_sim.$$.out 2>&1 &
sim=$!
"$bin/central_routing" --vehicle_ids 1,2,3,4,5,6,7,8 --lanes "$lanes" --simulated_time > /tmp/cpm_demo_routing.$$.out 2>&1 &
routing=$!
"$bin/cpm" routing watch --duration "${routing_seconds}s" --vehicles 1,2,3,4,5,6,7,8 --lanes "$lanes" --picture "$picture" \
  > /tmp/cpm_demo_watch.$$.out 2>&1 &
watch=$!
trap 'kill $sim $routing $watch 2>/dev/null || true' EXIT INT TERM
"$bin/cpm" lab clock --nodes firmware_sim_1,vehicle_bridge_1,central_routing --simulated --until "$((routing_seconds + 1))s" \
  || status=$?
wait $watch || status=$?
cat /tmp/cpm_demo_watch.$$.out
wait $routing 2>/dev/null || true
wait $sim 2>/dev/null || true
echo
if [ $status -eq 0 ]; then
  echo "demo: central_routing: $(tail -n 1 /tmp/cpm_demo_routing.$$.out)"
  echo "      Try the planner without DDS: build/bin/cpm routing simulate --lanes scenarios/lanes/intersection.json"
  echo "      --vehicles 12 --duration 60s (or --mode cpm_lab, cpm_lab's scheme, for comparison)."
else
  echo "demo: central routing FAILED (exit $status); central_routing said:" >&2
  tail -n 20 /tmp/cpm_demo_routing.$$.out >&2
fi
rm -f /tmp/cpm_demo_sim.$$.out /tmp/cpm_demo_routing.$$.out /tmp/cpm_demo_watch.$$.out
exit $status
