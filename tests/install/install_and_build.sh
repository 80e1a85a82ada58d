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
