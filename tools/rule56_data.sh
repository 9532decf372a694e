#!/usr/bin/env bash
# Rule 56's data (docs/training-log.md, sessions 44-47) in one folder, from this repository: the
# judging datasets and N's fifteen store sources (tools/training_data.sh), the two bitmap
# pools (tools/texture_pool.py), the planned sets tp, tq and roomsb, the sources' footprint
# shadows (tools/footprint_shadow.sh) and the store pool2.kps.
#
#   tools/rule56_data.sh [--plan-only] DIR
#
# --plan-only plans everything and renders nothing (a minute): training_data.sh's lines, then
# "NAME: N jobs, S camera samples, B distinct pool bitmaps in F scene files" for tp, tq, roomsb.
# Every step resumes where it stopped (renders on disk are kept, a pool or plan that exists is
# not made again), so the same command continues after an interruption. About 4e10 camera
# samples: 4.5 h of rendering on a 2-core Zen 4, 7 h on a 2-core Zen 3. Prints a line per step
# (TD_DONE ... R56_DATA_DONE). Environment: KPCN_BIN (default build/tools); renders run at
# nice 19. A dataset folder planned from another checkout path is refused by
# training_data.sh: continue a rebuild from the checkout that started it.
set -euo pipefail
plan_only=0
[ "${1:-}" != --plan-only ] || { plan_only=1; shift; }
[ $# -eq 1 ] || { echo "usage: tools/rule56_data.sh [--plan-only] DIR" >&2; exit 2; }
R=$(cd "$(dirname "$0")/.." && pwd)
B=${KPCN_BIN:-$R/build/tools}
DS=$B/kpcn-dataset/kpcn-dataset
[ -x "$DS" ] || { echo "rule56_data.sh: no kpcn-dataset at '$DS' (build first, or set KPCN_BIN)" >&2; exit 1; }
mkdir -p "$1"
T=$(cd "$1" && pwd)
cd "$T"
export KPCN_BIN=$B
opt=--no-store
[ $plan_only = 0 ] || opt=--plan-only
nice -n 19 "$R/tools/training_data.sh" $opt "$T/td" v1 v2val v3val roomsval roomsval2 \
  roomsval3 v2 v3 rooms rooms2 rooms9 rooms3 rooms4 v4a v4b rooms5 v4c v4d rooms6 rooms7 rooms8
echo "TD_DONE $(date)"
X="$R/testdata/scenes/textures/bricks.png $R/testdata/scenes/textures/gradient.png"
# shellcheck disable=SC2086 # X is two paths
{
  [ -d pool ] || /usr/bin/python3 "$R/tools/texture_pool.py" "$T/pool" --count 256 --seed 1 --exclude $X
  [ -d pool2 ] || /usr/bin/python3 "$R/tools/texture_pool.py" "$T/pool2" --count 1024 --seed 2 --exclude $X
}
plan() { # NAME SCENE_FOLDER OPTIONS...: plans NAME once, then renders what is missing
  local name=$1 scenes=$2
  shift 2
  [ -d "$name" ] || "$DS" plan --scenes "$scenes" -o "$name" --spp 16 --ref-spp 1024 \
    --resolution 160x160 --albedo-footprint 2 --no-preview "$@" >"$name.plan.txt"
  if [ $plan_only = 1 ]; then
    # the pool bitmaps the plan's scene files name (session 45 recorded these counts)
    local bitmaps files
    bitmaps=$(grep -rhoE 'pool_[0-9]+_[a-z]+\.png' "$name/scenes" | sort -u | wc -l)
    files=$(grep -rlE 'pool_[0-9]+_[a-z]+\.png' "$name/scenes" | wc -l)
    echo "$(basename "$name"): $(tail -n 1 "$name.plan.txt" | sed -E \
      's/^([0-9]+) jobs.*, ([0-9.e+]+) camera samples.*/\1 jobs, \2 camera samples/'), $bitmaps distinct pool bitmaps in $files scene files"
  else
    nice -n 19 "$DS" run "$name" --jobs 2 --threads-per-job 1
  fi
}
links() { # FOLDER SCENE...: FOLDER/SCENE -> testdata/scenes/SCENE
  local dir=$1
  shift
  mkdir -p "$dir"
  for s in "$@"; do ln -sfn "$R/testdata/scenes/$s" "$dir/"; done
}
plus() { echo "$*" | tr ' ' '+'; }
# tp (rule 54): the seven training scenes that hold bitmaps, pool
tp7="textured-room patterns-envmap living-room shelf corridor block-city bounce-light"
# shellcheck disable=SC2086
links scenes_tp $tp7
mkdir -p tpw
# shellcheck disable=SC2086
plan tpw/tp scenes_tp --variants 21 --seed 4401 --texture-swap 0.7 --texture-dir "$T/pool" \
  --split "train:$(plus $tp7)"
echo "TP_DONE $(date)"
# tq (session 45): all 17 training scenes, pool2
all17="cornell-box depth-discontinuities envmap-lighting glass-caustics glossy-mirror hard-soft-shadows
  materialtest sky-plastics textured-emitters living-room window-room corridor bounce-light
  textured-room block-city shelf patterns-envmap"
# shellcheck disable=SC2086
links scenes_tq $all17
# shellcheck disable=SC2086
plan tq scenes_tq --variants 8 --seed 5601 --texture-swap 0.7 --texture-bitmap 0.6 \
  --texture-dir "$T/pool2" --split "train:$(plus $all17)"
echo "TQ_DONE $(date)"
# roomsb (session 45): 48 new rooms, pool2
[ -d rooms_b ] || /usr/bin/python3 "$R/testdata/scenes/rooms.py" --count 48 --seed 5602 -o rooms_b >/dev/null
plan roomsb rooms_b --variants 1 --seed 5603 --camera 0.5 --texture-swap 0.8 --texture-bitmap 0.8 \
  --texture-dir "$T/pool2"
echo "ROOMSB_DONE $(date)"
[ $plan_only = 0 ] || exit 0
src=()
for d in v2 v3 rooms rooms2 rooms3 rooms4 v4a v4b rooms5 v4c v4d rooms6 rooms7 rooms8 rooms9; do
  nice -n 19 "$R/tools/footprint_shadow.sh" "$T/td/dataset/$d" "$T/fpds/$d"
  src+=("$T/fpds/$d")
done
echo "FP_DONE $(date)"
[ -f pool2.kps ] || nice -n 19 "$DS" patches "${src[@]}" tpw/tp tq roomsb -o pool2.kps --spp 16 \
  --per-image 48 --cull 0.9 --seed 1 --dtype f16
echo "R56_DATA_DONE $(date)"
