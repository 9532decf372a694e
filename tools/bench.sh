#!/usr/bin/env bash
# Runs every benchmark executable (bench_*) of a build and prints their figures.
#   tools/bench.sh [build-dir]      (build first with tools/setup.sh)
set -uo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
build=${1:-"$here/build"}
status=0
for b in $(find "$build/tests" -maxdepth 2 -type f -name 'bench_*' -perm -u+x | sort); do
  echo "=== $(basename "$b") ==="
  (cd "$(dirname "$b")" && "$b") || { echo "$(basename "$b") failed"; status=1; }
done
exit $status
