#!/usr/bin/env bash
# fuzz/run.sh BUILD_DIR SECONDS [TARGET...]: runs each fuzz target (all when none is named) for
# SECONDS with libFuzzer, two at a time, then prints one table: executions, speed, findings and
# inputs slower than 1 s per target. New inputs go to BUILD_DIR/corpus/<target>/ (beside the
# checked-in seeds, fuzz/corpus/<target>/, which are read, never written); findings go to
# BUILD_DIR/findings/<target>/. Exit status 1 when anything was found. CPM_FUZZ_RUNS=N ends a
# target after N executions if that comes first (./lab fuzz 3600 with CPM_FUZZ_RUNS=1000000: a
# million each, however long the slowest needs).
set -euo pipefail
build="$1" seconds="$2"
shift 2
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
fuzzer="$build/bin/cpm_fuzz"
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  mapfile -t targets < <(sed -n '/^set(cpm_fuzz_targets/,/)/p' "$here/CMakeLists.txt" | tr ' ()' '\n\n\n' | grep -v -e '^$' -e '^set$' -e '^cpm_fuzz_targets$')
fi

run_one() {
  local t="$1"
  mkdir -p "$build/corpus/$t" "$build/findings/$t" "$build/logs"
  # -timeout=1: an input that takes over a second is a finding (a "timeout-" file), as a crash is.
  CPM_FUZZ_TARGET="$t" "$fuzzer" -max_total_time="$seconds" -runs="${CPM_FUZZ_RUNS:--1}" -timeout=1 -rss_limit_mb=2048 \
    -print_final_stats=1 -artifact_prefix="$build/findings/$t/" \
    "$build/corpus/$t" "$here/corpus/$t" > "$build/logs/$t.log" 2>&1 || true
}

echo "fuzzing ${#targets[@]} targets, $seconds s each, two at a time (logs: $build/logs/)"
running=0
for t in "${targets[@]}"; do
  [ -d "$here/corpus/$t" ] || { echo "fuzz: no target '$t' (no folder fuzz/corpus/$t)" >&2; exit 2; }
  run_one "$t" &
  running=$((running + 1))
  if [ $running -ge 2 ]; then wait -n; running=$((running - 1)); fi
done
wait

status=0
printf '\n%-16s %12s %9s %9s %9s %7s\n' target executions 'exec/s' crashes 'over 1 s' corpus
for t in "${targets[@]}"; do
  log="$build/logs/$t.log"
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
  crashes=$(find "$build/findings/$t" -type f ! -name 'timeout-*' ! -name 'slow-unit-*' | wc -l)
  slow=$(find "$build/findings/$t" -type f \( -name 'timeout-*' -o -name 'slow-unit-*' \) | wc -l)
  corpus=$(find "$build/corpus/$t" "$here/corpus/$t" -type f | wc -l)
  printf '%-16s %12s %9s %9s %9s %7s\n' "$t" "${runs:-?}" "${rate:-?}" "$crashes" "$slow" "$corpus"
  if [ -z "$runs" ] || [ "$crashes" -gt 0 ] || [ "$slow" -gt 0 ]; then status=1; fi
done
if [ $status -ne 0 ]; then
  echo
  echo "findings (replay one: CPM_FUZZ_TARGET=<target> $fuzzer FILE; keep it as a regression case"
  echo "in fuzz/corpus/<target>/ once fixed):"
  find "$build/findings" -type f | sed 's/^/  /'
fi
exit $status
