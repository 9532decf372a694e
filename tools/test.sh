#!/usr/bin/env bash
# Sets up (Debian packages), builds and runs the whole kpcn test suite.
#   tools/test.sh [build-dir] [extra cmake args...]
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
build=${1:-"$here/build"}
shift || true
"$here/tools/setup.sh" "$build" "$@"
ctest --test-dir "$build" -j"$(nproc)" --output-on-failure --timeout 900
