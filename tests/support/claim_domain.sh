# Sourced by shell-based tests: claims a DDS domain id in 1..232 that no other test process
# holds (the same lock files as cpm_test::test_domain_id) and exports it as CPM_DOMAIN_ID.
# The lock is held on file descriptor 9 until the shell exits.
claim_test_domain() {
  mkdir -p /tmp/cpm_test_domains
  local start=$(( $$ % 232 )) i candidate
  for i in $(seq 0 231); do
    candidate=$(( 1 + (start + i) % 232 ))
    exec 9>"/tmp/cpm_test_domains/$candidate.lock"
    if flock -n 9; then
      export CPM_DOMAIN_ID=$candidate
      return 0
    fi
  done
  echo "no free DDS domain id in 1..232" >&2
  return 1
}
