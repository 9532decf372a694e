#!/bin/sh
# tools/rule56_data.sh --plan-only: rule 56's three planned sets plan as docs/training-log.md
# recorded them (sessions 44 and 45: jobs, camera samples and the distinct pool bitmaps their
# scene files name), nothing is rendered, and bad arguments are refused before anything is made.
# usage: test_rule56_data.sh SCRIPT KPCN_BIN
set -u
S=$1; B=$2
D=$(mktemp -d /tmp/kpcn_r56_XXXXXX)
trap 'rm -rf "$D"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
KPCN_BIN=$B bash "$S" --plan-only "$D/out" >"$D/plan.txt" 2>"$D/err" || fail "plan-only: $(cat "$D/err")"
for want in "tp: 308 jobs, 4.1e+09 camera samples, 147 distinct pool bitmaps" \
  "tq: 306 jobs, 4.07e+09 camera samples, 242 distinct pool bitmaps" \
  "roomsb: 192 jobs, 2.56e+09 camera samples, 220 distinct pool bitmaps"; do
  grep -qF "$want" "$D/plan.txt" || fail "no line '$want' in: $(cat "$D/plan.txt")"
done
# the 21 datasets are training_data.sh's (test_training_data checks their figures)
[ "$(grep -c ' jobs, ' "$D/plan.txt")" -eq 24 ] || fail "expected 21 + 3 plan lines: $(cat "$D/plan.txt")"
n=$(find "$D/out" -name '*.exr' | wc -l)
[ "$n" -eq 0 ] || fail "--plan-only rendered $n files"
# bad arguments: usage (exit 2), no binaries (exit 1); neither creates DIR
bash "$S" 2>/dev/null; [ $? -eq 2 ] || fail "no DIR: expected exit 2"
bash "$S" --plan-only "$D/a" "$D/b" 2>/dev/null; [ $? -eq 2 ] || fail "two DIRs: expected exit 2"
KPCN_BIN=$D/nothing bash "$S" "$D/x" 2>"$D/err2"; [ $? -eq 1 ] || fail "no binaries: expected exit 1"
grep -q "no kpcn-dataset" "$D/err2" || fail "no binaries: message '$(cat "$D/err2")'"
[ ! -e "$D/x" ] || fail "a refused call created DIR"
echo "rule56_data: tp, tq and roomsb plan as recorded; refusals clean"
