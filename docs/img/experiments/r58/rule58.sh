#!/usr/bin/env bash
# Rule 58 (docs/training-log.md, session 60): arms A0 and A1 from R on pool2.kps, side by side.
set -euo pipefail
R=/work/main; B=$R/build-dev/tools; T=/work/s56; V=$T/td/dataset; O=/work/s60
while ! grep -q R56_DATA_DONE $T/data.log || [ ! -f $T/pool2.kps ]; do sleep 30; done
echo "data done $(date)"
arm() { # NAME EXTRA...
  local a=$1; shift
  mkdir -p $O/$a/snap
  local resume=(); [ ! -f $O/$a/model.safetensors.ckpt ] || resume=(--resume)
  $B/kpcn-train/kpcn-train --store $T/pool2.kps -o $O/$a/model.safetensors --preset cpu \
    --init $R/testdata/models/kpcn-cpu.safetensors --freeze specular --stage1-iters 0 --loss l1 \
    --loss2 rell1-sg --lr 3.75e-5 --decay-every 500 --seed 58 --threads 1 --iters 3000 \
    --val-every 500 --ckpt-every 250 --snapshots $O/$a/snap \
    --val "$O/fp16.exr,$V/v1/renders/textures/v000_ref4096spp.exr" \
    --val "$V/v1/renders/diffuse-interreflection/v000_16spp.exr,$V/v1/renders/diffuse-interreflection/v000_ref4096spp.exr" \
    --val "$V/roomsval/renders/room-202-0/v000_16spp.exr,$V/roomsval/renders/room-202-0/v000_ref1024spp.exr" \
    --val "$V/roomsval/renders/room-202-1/v000_16spp.exr,$V/roomsval/renders/room-202-1/v000_ref1024spp.exr" \
    "${resume[@]}" "$@" >> $O/$a/train.log 2>&1
}
arm A0 & arm A1 --loss-margin 10 & wait
echo "arms done $(date)"
