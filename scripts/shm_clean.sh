#!/usr/bin/env bash
# Removes Fast DDS shared-memory files (/dev/shm/fastrtps_*, sem.fastrtps_*) that no running
# process has open or mapped. A process killed with SIGKILL leaves them behind, sometimes with
# a port mutex still locked; a later participant that picks that port then waits forever.
# `fastdds shm clean` removes only part of them. Safe while other DDS programs run: a file in
# use is kept. Also cpm's markers of dead ports (cpm_dead_fastrtps_port*, never held open).
set -uo pipefail
shopt -s nullglob
in_use=$( (ls -l /proc/[0-9]*/fd 2>/dev/null; cat /proc/[0-9]*/maps 2>/dev/null) | grep -o '/dev/shm/[^ ]*' | sort -u)
removed=0
for f in /dev/shm/fastrtps_* /dev/shm/sem.fastrtps_* /dev/shm/fast_datasharing_* /dev/shm/cpm_dead_fastrtps_port*; do
  if ! grep -qxF "$f" <<<"$in_use"; then
    rm -f "$f" && removed=$((removed + 1))
  fi
done
echo "shm_clean: removed $removed unused Fast DDS shared-memory files"
