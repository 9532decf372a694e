#!/bin/bash
# rule 59's data: render tr and roomsc, then pool3.kps (pool2's sources + tr + roomsc)
set -e
cd /work/s63
DS=/work/main/build-dev/tools/kpcn-dataset/kpcn-dataset
nice -n 19 $DS run tr --jobs 2 --threads-per-job 1
echo "TR_DONE $(date)"
nice -n 19 $DS run roomsc --jobs 2 --threads-per-job 1
echo "ROOMSC_DONE $(date)"
T=/work/s56
src=()
for d in v2 v3 rooms rooms2 rooms3 rooms4 v4a v4b rooms5 v4c v4d rooms6 rooms7 rooms8 rooms9; do src+=("$T/fpds/$d"); done
[ -f pool3.kps ] || nice -n 19 $DS patches "${src[@]}" $T/tpw/tp $T/tq $T/roomsb tr roomsc -o pool3.kps --spp 16 \
  --per-image 48 --cull 0.9 --seed 1 --dtype f16
echo "POOL3_DONE $(date)"
