#!/usr/bin/env bash
# Removes the network namespaces a test or benchmark that made hosts (NamespaceHosts: cpmsw<pid>,
# cpmh<pid>_<i>; the partition test: cpmA<pid>, cpmB<pid>; --link veth: cpmbench<pid>_a|b) could
# not remove itself because it was killed (a ctest timeout, a CI job cut off). Only those of processes that no longer run: a test's namespaces in use are kept.
set -uo pipefail
[ "$(id -u)" = 0 ] || exit 0
removed=0
for ns in $(ip netns list 2>/dev/null | awk '{print $1}'); do
  [[ "$ns" =~ ^cpm(sw|h|A|B|bench)([0-9]+)(_[0-9a-z]+)?$ ]] || continue
  pid="${BASH_REMATCH[2]}"
  kill -0 "$pid" 2>/dev/null && continue
  ip netns pids "$ns" 2>/dev/null | xargs -r kill -9 2>/dev/null
  ip netns del "$ns" && removed=$((removed + 1))
done
echo "netns_clean: removed $removed network namespace(s) of test processes that are gone"
