#!/usr/bin/env bash
# A rendered dataset with its noisy inputs made again with the albedo footprint, beside it: DST
# becomes a kpcn-dataset folder whose SPP-spp noisy renders are rendered again with
# kpcn-render --albedo-footprint K (the manifest's seed, scene file and size, so only the
# albedo differs: docs/renderer.md, "Albedo footprint") and whose every other file is a link
# into SRC. `kpcn-dataset patches DST` then builds a store of footprint inputs against the same
# references (docs/training-log.md, sessions 41 and 44).
#   tools/footprint_shadow.sh SRC DST
# Environment: K (default 2), SPP (default 16), KPCN_BIN (default build/tools), THREADS (2).
# Resumable: a render already in DST is kept; each is written to a part file and renamed.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
die() { echo "footprint_shadow.sh: $*" >&2; exit 1; }
[ $# -eq 2 ] || { echo "usage: tools/footprint_shadow.sh SRC DST" >&2; exit 2; }
k=${K:-2}
spp=${SPP:-16}
[[ $k =~ ^[0-9]+$ ]] && [ "$k" -ge 2 ] && [ "$k" -le 16 ] || die "K '$k' is not an integer in 2..16"
[[ $spp =~ ^[0-9]+$ ]] && [ "$spp" -ge 1 ] || die "SPP '$spp' is not a positive integer"
render=${KPCN_BIN:-$here/build/tools}/kpcn-render/kpcn-render
[ -x "$render" ] || die "no kpcn-render at '$render' (build first, or set KPCN_BIN)"
[ -f "$1/manifest.jsonl" ] && [ -d "$1/renders" ] || die "'$1' is not a rendered kpcn-dataset folder"
src=$(cd "$1" && pwd)
dst=$(realpath -m "$2")
[ "$src" != "$dst" ] || die "SRC and DST are the same folder"
# the noisy renders to make again: "out seed scene_file WxH" per manifest line
list=$(grep '"kind":"noisy"' "$src/manifest.jsonl" | { grep "\"spp\":$spp," || true; } |
  /usr/bin/python3 -c "
import json, sys
for l in sys.stdin:
    j = json.loads(l)
    print(j['out'], j['seed'], j['scene_file'], '%dx%d' % (j['width'], j['height']))")
[ -n "$list" ] || die "'$src' has no ${spp}-spp noisy render in its manifest"
mkdir -p "$dst" # only now: a refused call leaves nothing behind
# everything but renders/ is a link; renders/ is rebuilt file by file
for e in "$src"/*; do
  [ "$(basename "$e")" = renders ] || ln -sfn "$e" "$dst/$(basename "$e")"
done
(cd "$src" && find renders -type f ! -name '*.part*') | while read -r f; do
  mkdir -p "$dst/$(dirname "$f")"
  [ -e "$dst/$f" ] || ln -s "$src/$f" "$dst/$f"
done
n=0
while read -r out seed sf res; do
  [ -f "$src/$out" ] || continue # not rendered (or rejected) in SRC: no pair to shadow
  [ -L "$dst/$out" ] || [ ! -e "$dst/$out" ] || continue # made by an earlier call
  part="$dst/${out%.exr}.part$$.exr"
  "$render" "$src/$sf" -o "$part" --spp "$spp" --seed "$seed" --resolution "$res" \
    --threads "${THREADS:-2}" --albedo-footprint "$k" --quiet || { rm -f "$part"; die "render of $out failed"; }
  rm -f "$dst/$out"
  mv "$part" "$dst/$out"
  n=$((n + 1))
done <<<"$list"
echo "footprint_shadow.sh: $dst: $n ${spp}-spp renders made with --albedo-footprint $k"
