#!/usr/bin/env bash
# docs/training.md's "Train your own: a quick start", run as written (its first ```sh block,
# from the repository root's testdata) with 10 iterations instead of 300, so the documented
# commands keep working: plan, run, two patch stores, a fine-tune validated with --val-store,
# and kpcntool measuring the held-out render.
# usage: test_quickstart.sh SOURCE_DIR BIN_DIR (BIN_DIR: the build's tools/)
set -euo pipefail
src=$1
bin=$2
work=$(mktemp -d /tmp/kpcn_quick_XXXXXX)
trap 'rm -rf "$work"' EXIT
export PATH="$bin/kpcn-dataset:$bin/kpcn-train:$bin/kpcntool:$bin/kpcn-render:$PATH"
# the block, its first line after "## Train your own" and "```sh" to the closing fence
script=$(awk '/^## Train your own/ {s = 1} s && /^```sh$/ {b = 1; next} b && /^```$/ {exit} b' \
  "$src/docs/training.md")
[ -n "$script" ] || { echo "FAIL: no quick-start block in docs/training.md" >&2; exit 1; }
grep -q -- '--iters 300' <<<"$script" || { echo "FAIL: the block no longer says --iters 300" >&2; exit 1; }
script=${script//--iters 300/--iters 10}
ln -s "$src/testdata" "$work/testdata"
cd "$work"
bash -euo pipefail -c "$script" >out.txt 2>err.txt || {
  echo "FAIL: the quick start failed:" >&2
  cat err.txt >&2
  exit 1
}
grep -q '"relmse"' out.txt || { echo "FAIL: no relMSE printed: $(cat out.txt)" >&2; exit 1; }
grep -q 'validation inputs as rendered (noisy)' err.txt ||
  { echo "FAIL: no noisy validation figure: $(cat err.txt)" >&2; exit 1; }
echo "test_quickstart: ok ($(cat out.txt))"
