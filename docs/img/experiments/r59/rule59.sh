#!/usr/bin/env bash
# Rule 59 (docs/training-log.md, session 63): run U, rule 58's arm A0 on pool3.kps.
# The data: /work/s63/data.sh (tr and roomsc rendered, then pool3.kps), commands in the log.
set -euo pipefail
R=/work/main; B=$R/build-dev/tools; T=/work/s56; V=$T/td/dataset; O=/work/s63
while ! grep -q POOL3_DONE $O/data.log || [ ! -f $O/pool3.kps ]; do sleep 30; done
echo "data done $(date)"
mkdir -p $O/U/snap
resume=(); [ ! -f $O/U/model.safetensors.ckpt ] || resume=(--resume)
$B/kpcn-train/kpcn-train --store $O/pool3.kps -o $O/U/model.safetensors --preset cpu \
  --init $R/testdata/models/kpcn-cpu.safetensors --freeze specular --stage1-iters 0 --loss l1 \
  --loss2 rell1-sg --lr 3.75e-5 --decay-every 500 --seed 58 --threads 1 --iters 3000 \
  --val-every 500 --ckpt-every 250 --snapshots $O/U/snap \
  --val "/work/s60/fp16.exr,$V/v1/renders/textures/v000_ref4096spp.exr" \
  --val "$V/v1/renders/diffuse-interreflection/v000_16spp.exr,$V/v1/renders/diffuse-interreflection/v000_ref4096spp.exr" \
  --val "$V/roomsval/renders/room-202-0/v000_16spp.exr,$V/roomsval/renders/room-202-0/v000_ref1024spp.exr" \
  --val "$V/roomsval/renders/room-202-1/v000_16spp.exr,$V/roomsval/renders/room-202-1/v000_ref1024spp.exr" \
  "${resume[@]}" >> $O/U/train.log 2>&1
echo "U done $(date)"
