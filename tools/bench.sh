#!/usr/bin/env bash
# Runs every benchmark executable (bench_*) of a build and prints their figures.
#   tools/bench.sh [build-dir]      (build first with tools/setup.sh)
set -uo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
build=${1:-"$here/build"}
[ -d "$build/tests" ] || { echo "bench.sh: '$build' is not a kpcn build folder (build first)" >&2; exit 1; }
build=$(cd "$build" && pwd) # absolute: each benchmark runs from its own folder
status=0
ran=0
# what the figures were measured with: versions and the instruction set in use (AVX-512 and
# AVX2 hosts differ 2-5x), and the CPU
kr=$build/tools/kpcn-render/kpcn-render
[ ! -x "$kr" ] || "$kr" --version | sed -n 2p
awk -F': ' '/^model name/ && !n {n = $2} /^cpu family/ && !f {f = $2} /^model[[:space:]]*:/ && !m {m = $2}
  END {if (n != "") printf "cpu: %s (family %s, model %s), %d logical CPUs\n", n, f, m, nproc}' \
  nproc="$(nproc)" /proc/cpuinfo 2>/dev/null
while IFS= read -r -d '' b; do
  echo "=== $(basename "$b") ==="
  ran=$((ran + 1))
  (cd "$(dirname "$b")" && "$b") || { echo "$(basename "$b") failed"; status=1; }
done < <(find "$build/tests" -maxdepth 2 -type f -name 'bench_*' -perm -u+x -print0 | sort -z)
[ $ran -gt 0 ] || { echo "bench.sh: no bench_* programs under '$build/tests'" >&2; exit 1; }
exit $status
