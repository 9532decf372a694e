#!/usr/bin/env bash
# Rebuilds the training data of N (the shipped model from session 38 to 52, which the shipped
# model R was trained from) and the images the judging rules use, from the recipes of
# docs/dataset.md, in one folder: the scene folders (links into testdata/scenes and procedural
# rooms), the 21 kpcn-dataset datasets, the two 4096-spp references of the held-out scenes and
# the patch store `rooms9v.kps` (docs/training-log.md, rule 50's store). R's store is built on
# top of this by tools/rule56_data.sh.
#
#   tools/training_data.sh [--plan-only] [--no-store] DIR [DATASET ...]
#
# DATASET: only these (default: all, in the order the sessions made them). --plan-only writes
# the scenes and plans and prints "NAME: N jobs, S camera samples" per dataset, rendering
# nothing (seconds; tests/dataset/test_training_data.sh checks it against the figures in
# docs/dataset.md). --no-store renders but does not build rooms9v.kps (24 GB).
# Resumable: a dataset already planned is checked against this recipe's plan (a dataset planned
# otherwise is an error), `kpcn-dataset run` renders only what is missing, the store is built
# only if absent. Rendering all of it is about 3.1e10
# camera samples, some 4.5 hours on 2 cores. Environment: KPCN_BIN (default build/tools),
# JOBS (parallel render jobs, default 2; one thread each, as the recipes).
#
# The renders are the current renderer's. The shipped model's lineage trained on renders of
# the same plans made by the renderer of their session, so where the renderer has changed
# since, the files differ (docs/dataset.md, "N's data and the judging sets in one command",
# has what session 40 found reproduced).
set -euo pipefail
shopt -s inherit_errexit
here=$(cd "$(dirname "$0")/.." && pwd)
plan_only=0 store=1
while [ $# -gt 0 ]; do
  case $1 in
    --plan-only) plan_only=1; shift ;;
    --no-store) store=0; shift ;;
    -h | --help) sed -n '2,22p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    -*) echo "training_data.sh: unknown option '$1'" >&2; exit 2 ;;
    *) break ;;
  esac
done
[ $# -ge 1 ] || { echo "usage: tools/training_data.sh [--plan-only] [--no-store] DIR [DATASET ...]" >&2; exit 2; }
out=$1
shift
# every dataset, in the order the sessions made them
all="v1 v2 v2val v3 v3val rooms roomsval rooms2 roomsval2 rooms3 rooms4 v4a v4b roomsval3 rooms5 v4c v4d rooms6 rooms7 rooms8 rooms9"
# rooms9v.kps's sources (docs/dataset.md, "Session 37" and "Session 38")
store_sources="v2 v3 rooms rooms2 rooms3 rooms4 v4a v4b rooms5 v4c v4d rooms6 rooms7 rooms8 rooms9"
names=${*:-$all}
for d in $names; do
  [[ " $all " == *" $d "* ]] || { echo "training_data.sh: unknown dataset '$d' (one of: $all)" >&2; exit 2; }
done
bin=${KPCN_BIN:-$here/build/tools}
ds_tool="$bin/kpcn-dataset/kpcn-dataset"
render="$bin/kpcn-render/kpcn-render"
jobs=${JOBS:-2}
[ -x "$ds_tool" ] || { echo "training_data.sh: no kpcn-dataset at '$ds_tool' (build first, or set KPCN_BIN)" >&2; exit 1; }
scenes=$here/testdata/scenes
mkdir -p "$out"
out=$(cd "$out" && pwd)
cd "$out"

# Scene folders: `plan` takes every scene of a folder and refuses one in no split, so each
# dataset plans a folder holding just its scenes (links; meshes/, textures and the envmap
# along where its scenes need them).
link() { # FOLDER NAME... : FOLDER/NAME -> testdata/scenes/NAME
  local dir=$1
  shift
  mkdir -p "$dir"
  for s in "$@"; do ln -sfn "$scenes/$s" "$dir/$s"; done
}
train8="cornell-box depth-discontinuities envmap-lighting glass-caustics glossy-mirror hard-soft-shadows materialtest sky-plastics"
v3train="living-room window-room corridor bounce-light textured-room block-city shelf patterns-envmap"
# shellcheck disable=SC2086 # the lists are words
{
  link v1scenes $train8 thin-geometry diffuse-interreflection textures
  link v2scenes $train8 textured-emitters thin-geometry diffuse-interreflection textures
  link valscenes $train8 textured-emitters meshes
  link v3scenes $v3train train-textures
}
mkdir -p v3scenes/materialtest
ln -sfn "$scenes/materialtest/envmap.hdr" v3scenes/materialtest/envmap.hdr
plus() { echo "$*" | tr ' ' '+'; }
split1="train:$(plus $train8),val:thin-geometry,test:diffuse-interreflection+textures"
split2="train:$(plus $train8 textured-emitters),val:thin-geometry,test:diffuse-interreflection+textures"
splitval="train:$(plus $train8 textured-emitters)"
split3="train:$(plus $v3train)"
rooms() { # FOLDER SEED COUNT [OUTSIDE]: testdata/scenes/rooms.py's rooms (a pure function of seed and index)
  [ -d "rooms/$1" ] || /usr/bin/python3 "$scenes/rooms.py" --count "$3" --seed "$2" \
    ${4:+--outside "$4"} -o "rooms/$1" >/dev/null
}

# name | scene folder | plan options (all: --spp 4,16,64 --ref-spp 1024 --resolution 160x160)
v3opt="--texture-swap 0.3 --texture-dir $scenes/train-textures"
spec() {
  case $1 in
    v1) echo "v1scenes --variants 6 --seed 7 --texture-swap 0 --split $split1" ;;
    v2) echo "v2scenes --variants 12 --seed 11 --texture-swap 0.3 --split $split2" ;;
    v2val) echo "valscenes --variants 2 --seed 12 --texture-swap 0.3 --split $splitval" ;;
    v3) echo "v3scenes --variants 8 --seed 13 $v3opt --split $split3" ;;
    v3val) echo "v3scenes --variants 2 --seed 14 $v3opt --split $split3" ;;
    rooms) rooms train 101 32; echo "rooms/train --variants 1 --seed 31 --camera 0.5 --texture-swap 0" ;;
    roomsval) rooms val 202 12; echo "rooms/val --variants 0 --seed 32 --no-preview" ;;
    rooms2) rooms train2 303 48; echo "rooms/train2 --variants 1 --seed 33 --camera 0.5 --texture-swap 0" ;;
    roomsval2) rooms val2 404 12; echo "rooms/val2 --variants 0 --seed 34 --no-preview" ;;
    rooms3) rooms train3 505 48; echo "rooms/train3 --variants 0 --seed 35" ;;
    rooms4) rooms train4 606 36 0.5; echo "rooms/train4 --variants 0 --seed 41" ;;
    v4a) echo "valscenes --variants 1 --seed 42 --texture-swap 0.3 --split $splitval" ;;
    v4b) echo "v3scenes --variants 2 --seed 43 $v3opt --split $split3" ;;
    roomsval3) rooms val3 808 12 1; echo "rooms/val3 --variants 0 --seed 44 --no-preview" ;;
    rooms5) rooms train5 909 48 0.5; echo "rooms/train5 --variants 0 --seed 51" ;;
    v4c) echo "v3scenes --variants 2 --seed 53 $v3opt --split $split3" ;;
    v4d) echo "valscenes --variants 1 --seed 52 --texture-swap 0.3 --split $splitval" ;;
    rooms6) rooms train6 1111 96 0.5; echo "rooms/train6 --variants 0 --seed 61" ;;
    rooms7) rooms train7 1212 96 0.5; echo "rooms/train7 --variants 0 --seed 71" ;;
    rooms8) rooms train8 1313 96 0.5; echo "rooms/train8 --variants 0 --seed 81" ;;
    rooms9) rooms train9 1414 96 0.5; echo "rooms/train9 --variants 0 --seed 91" ;;
  esac
}
# the held-out scenes' 4096-spp references (docs/dataset.md; tools/results.sh REF2_SPP=4096),
# made as soon as v1 is rendered: the judging of models needs them before the training sets
refs4096() {
  for s in diffuse-interreflection:40961 textures:40962; do
    f="dataset/v1/renders/${s%%:*}/v000_ref4096spp.exr"
    [ -f "$f" ] || (cd dataset/v1 && "$render" "scenes/${s%%:*}/v000.json" -o "${f#dataset/v1/}" \
      --spp 4096 --seed "${s##*:}" --threads 1 --resolution 160x160 --color-only --quiet)
  done
}
# Each dataset is planned afresh (a second or two) into a scratch folder: moved into place the
# first time; later, compared with the plan in place, so that a resumed rebuild never renders
# into a dataset planned with other options or by other code.
scratch="$out/.plan.$$"
trap 'rm -rf "$scratch"' EXIT
for d in $names; do
  s=$(spec "$d")
  read -r -a opts <<<"$s"
  rm -rf "$scratch"
  mkdir -p "$scratch"
  line=$("$ds_tool" plan --scenes "${opts[@]:0:1}" -o "$scratch/$d" "${opts[@]:1}" --spp 4,16,64 \
    --ref-spp 1024 --resolution 160x160 | tail -n 1)
  if [ ! -e "dataset/$d" ]; then
    mkdir -p dataset
    mv "$scratch/$d" "dataset/$d"
  elif [ ! -f "dataset/$d/manifest.jsonl" ]; then
    echo "training_data.sh: $out/dataset/$d exists but holds no manifest.jsonl: move it away" >&2
    exit 1
  elif ! cmp -s "$scratch/$d/manifest.jsonl" "dataset/$d/manifest.jsonl" ||
    ! diff -r -q "$scratch/$d/scenes" "dataset/$d/scenes" >/dev/null; then
    echo "training_data.sh: $out/dataset/$d was planned otherwise (its manifest or scene files" \
      "differ from this recipe's plan): move it away" >&2
    exit 1
  fi
  echo "$d: $(echo "$line" | sed -E 's/^([0-9]+) jobs.*, ([0-9.e+]+) camera samples.*/\1 jobs, \2 camera samples/')"
  [ $plan_only = 1 ] || "$ds_tool" run "dataset/$d" --jobs "$jobs" --threads-per-job 1
  [ $plan_only = 1 ] || [ "$d" != v1 ] || refs4096
done
[ $plan_only = 0 ] || exit 0

if [ $store = 1 ] && [ ! -f rooms9v.kps ]; then
  src=()
  for d in $store_sources; do
    [ -f "dataset/$d/manifest.jsonl" ] || { echo "training_data.sh: rooms9v.kps needs dataset $d" >&2; exit 1; }
    src+=("dataset/$d")
  done
  "$ds_tool" patches "${src[@]}" -o rooms9v.kps --spp 4,16,64 --per-image 32 --cull 0.9 --seed 1 \
    --dtype f16
fi
