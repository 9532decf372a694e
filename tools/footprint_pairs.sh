#!/usr/bin/env bash
# The albedo footprint's effect on a dataset's 16-spp pairs: each noisy render is made again
# with kpcn-render --albedo-footprint K (its manifest seed, scene file and size), both are
# denoised with MODEL and measured (relMSE, RGB) against the pair's reference.
#   tools/footprint_pairs.sh MODEL DATASET_DIR[:VARIANTS] ...
# VARIANTS: the variants to take, comma-separated (e.g. v001,v002; default all). Prints one
# TSV line per pair: dataset, scene, variant, relMSE plain, relMSE with the footprint.
# Environment: K (default 2), SPP (default 16), KPCN_BIN (default build/tools), THREADS (2),
# DENOISE_OPTS (appended to --denoise:model=MODEL, e.g. ":exposure=0.146227151"), PLAIN (1; 0
# skips the plain render's denoise and prints '-' for it: half the time, tools/judge_textures.py).
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
[ $# -ge 2 ] || { echo "usage: tools/footprint_pairs.sh MODEL DATASET_DIR[:VARIANTS] ..." >&2; exit 2; }
model=$1
shift
k=${K:-2}
spp=${SPP:-16}
bin=${KPCN_BIN:-$here/build/tools}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
rel() { # DENOISE-INPUT REFERENCE (kpcntool's own message when it fails, then this one)
  local j
  j=$("$bin/kpcntool/kpcntool" "$1" --denoise:model="$model${DENOISE_OPTS:-}" "$2" --ch R,G,B \
    --relmse --json) || { echo "footprint_pairs.sh: measuring '$1' against '$2' failed" >&2; return 1; }
  /usr/bin/python3 -c "import json,sys; print(json.loads(sys.argv[1])['relmse'])" "$j"
}
for arg in "$@"; do
  ds=${arg%%:*}
  want=""
  [ "$arg" != "$ds" ] && want=",${arg#*:},"
  [ -f "$ds/manifest.jsonl" ] || { echo "footprint_pairs.sh: no '$ds/manifest.jsonl'" >&2; exit 1; }
  grep '"kind":"noisy"' "$ds/manifest.jsonl" | grep "\"spp\":$spp," |
    /usr/bin/python3 -c "
import json, sys
for l in sys.stdin:
    j = json.loads(l)
    print('v%03d' % j['variant'], j['scene'], j['scene_file'], j['seed'], '%dx%d' % (j['width'], j['height']), j['out'])" |
    while read -r v scene sf seed res out; do
      [ -z "$want" ] || [[ $want == *",$v,"* ]] || continue
      noisy=$ds/$out
      ref=${noisy%_${spp}spp.exr}_ref1024spp.exr
      [ -f "$noisy" ] && [ -f "$ref" ] || continue
      "$bin/kpcn-render/kpcn-render" "$ds/$sf" -o "$tmp/fp.exr" --spp "$spp" --seed "$seed" \
        --resolution "$res" --threads "${THREADS:-2}" --albedo-footprint "$k" --quiet
      plain=-
      [ "${PLAIN:-1}" = 0 ] || plain=$(rel "$noisy" "$ref")
      # assigned first: a failure inside printf's arguments would not stop the script
      fp=$(rel "$tmp/fp.exr" "$ref")
      printf '%s\t%s\t%s\t%s\t%s\n' "$(basename "$ds")" "$scene" "$v" "$plain" "$fp"
    done
done
