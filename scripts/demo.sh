#!/usr/bin/env bash
# ./lab demo: a writer publishes 4 simulated vehicles' VehicleState at 50 Hz (valid 60 ms
# after creation); a monitor reads them with one MultiVehicleReader and prints each vehicle's
# newest valid state and its age once a second. Both stop by themselves after ~5 s.
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
if [ $status -eq 0 ]; then
  echo "demo: the monitor saw every vehicle's newest valid state. Each sample becomes valid 60 ms"
  echo "      after it was created, so 'since created' is 60..80 ms and the age (time since it became"
  echo "      valid) stays within one 20 ms period: newer samples exist but are not valid yet."
else
  echo "demo: FAILED (exit $status)" >&2
fi
exit $status
