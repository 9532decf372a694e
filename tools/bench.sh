#!/usr/bin/env bash
# Runs every benchmark executable (bench_*) of a build and prints their figures.
#   tools/bench.sh [build-dir]      (build first with tools/setup.sh)
set -uo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
build=${1:-"$here/build"}
build=$(cd "$build" && pwd) # absolute: each benchmark runs from its own folder
status=0
while IFS= read -r -d '' b; do
  echo "=== $(basename "$b") ==="
  (cd "$(dirname "$b")" && "$b") || { echo "$(basename "$b") failed"; status=1; }
done < <(find "$build/tests" -maxdepth 2 -type f -name 'bench_*' -perm -u+x -print0 | sort -z)
exit $status
