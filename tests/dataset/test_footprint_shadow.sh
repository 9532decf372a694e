#!/bin/sh
# tools/footprint_shadow.sh on a tiny real dataset of the textured scene: its 4-spp inputs are
# made again byte for byte as kpcn-render --albedo-footprint 2 makes them (and differ from the
# plain ones), every other file is a link to the source, a second call renders nothing,
# kpcn-dataset patches builds a store from the shadow, bad input is a clear error.
# usage: test_footprint_shadow.sh SCRIPT KPCN_DATASET KPCN_RENDER SCENES_DIR
set -u
S=$1; DS=$2; R=$3; SC=$4
D=$(mktemp -d /tmp/kpcn_fpshadow_XXXXXX)
trap 'rm -rf "$D"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
B=$(dirname "$(dirname "$R")")
mkdir -p "$D/scenes" && ln -s "$SC/textures" "$D/scenes/textures"
"$DS" plan --scenes "$D/scenes" -o "$D/src" --variants 1 --seed 3 --spp 4 --ref-spp 16 \
  --resolution 40x40 --camera 0 --no-preview --split train:textures >/dev/null || fail "plan"
"$DS" run "$D/src" --jobs 1 --threads-per-job 2 >/dev/null 2>&1 || fail "run"
KPCN_BIN=$B SPP=4 bash "$S" "$D/src" "$D/fp" >"$D/out" 2>"$D/err" || fail "shadow: $(cat "$D/err")"
grep -q "2 4-spp renders made with --albedo-footprint 2" "$D/out" || fail "count: $(cat "$D/out")"
grep '"kind":"noisy"' "$D/src/manifest.jsonl" | sed -E 's/.*"scene_file":"([^"]+)".*"seed":"?([0-9]+)"?.*"out":"([^"]+)".*/\1 \2 \3/' |
  while read -r sf seed out; do
    [ -f "$D/fp/$out" ] && [ ! -L "$D/fp/$out" ] || fail "$out not rendered in the shadow"
    "$R" "$D/src/$sf" -o "$D/want.exr" --spp 4 --seed "$seed" --resolution 40x40 --threads 1 \
      --albedo-footprint 2 --quiet || fail "direct render"
    cmp -s "$D/want.exr" "$D/fp/$out" || fail "$out is not kpcn-render --albedo-footprint 2's"
    ! cmp -s "$D/src/$out" "$D/fp/$out" || fail "$out is the plain render (no bitmap seen?)"
  done || exit 1
for f in manifest.jsonl scenes; do
  [ -L "$D/fp/$f" ] && [ "$(readlink "$D/fp/$f")" = "$D/src/$f" ] || fail "$f is not a link to the source"
done
n=$(find "$D/fp/renders" -name '*ref16spp.exr' -type l | wc -l)
[ "$n" -eq 2 ] || fail "the references are not links ($n)"
KPCN_BIN=$B SPP=4 bash "$S" "$D/src" "$D/fp" >"$D/out" 2>&1 || fail "second call"
grep -q ": 0 4-spp renders" "$D/out" || fail "second call rendered again: $(cat "$D/out")"
"$DS" patches "$D/fp" -o "$D/s.kps" --spp 4 --per-image 2 --size 16 >/dev/null 2>"$D/err" ||
  fail "patches on the shadow: $(cat "$D/err")"
bad() {
  pat=$1; shift
  if env KPCN_BIN="$B" "$@" >"$D/out" 2>"$D/err"; then fail "accepted: $*"; fi
  grep -qF -- "$pat" "$D/err" || fail "message lacks '$pat': $(cat "$D/err")"
}
bad "is not a rendered kpcn-dataset folder" bash "$S" "$D/scenes" "$D/x"
bad "are the same folder" bash "$S" "$D/src" "$D/src"
bad "is not an integer in 2..16" K=1 bash "$S" "$D/src" "$D/y"
bad "has no 8-spp noisy render" SPP=8 bash "$S" "$D/src" "$D/z"
[ ! -e "$D/z" ] && [ ! -e "$D/x" ] && [ ! -e "$D/y" ] || fail "a refused call left a folder behind"
echo "test_footprint_shadow: ok"
