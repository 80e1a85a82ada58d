#!/usr/bin/env bash
# The tests that assert a car's or a timer's rate, five times in a row with a busy loop on every
# core (their cars run --realtime, as a real car would). Run from the project root after
# ./lab build; extra arguments go to ctest (e.g. --repeat until-fail:10).
#   tests/under_load.sh [CTEST ARGS...]
set -euo pipefail
build="${CPM_BUILD_DIR:-$(cd "$(dirname "$0")/.." && pwd)/build}"
rate_tests='^(VehicleEndToEnd\.|DashCam\.|RealtimeProcess\.|TimerTest\.|LabAcrossHosts\.EachCarRunsOnItsHost)'
spinners=()
cleanup() { for p in "${spinners[@]}"; do kill "$p" 2>/dev/null || true; done; }
trap cleanup EXIT
for _ in $(seq "$(nproc)"); do
  ( while :; do :; done ) &
  spinners+=($!)
done
echo "under_load: $(nproc) busy loop(s) running (pids ${spinners[*]})"
cd "$build"
ctest --output-on-failure -R "$rate_tests" --repeat until-fail:5 "$@"
