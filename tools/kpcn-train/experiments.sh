#!/usr/bin/env bash
# The seed's training experiments (chapter 6) at small scale, each run with the SAME wall-clock
# budget, producing per-run CSV logs + PNG curves and combined comparison plots + a summary CSV.
#
#   A. loss and learning rate (seed Fig. 6.1, 6.2): stage-1 training with
#        l1  lr 1e-3 | l2 (MSE) lr 1e-3 | l2 (MSE) lr 1e-5
#   B. depth (seed Table 6.1, Fig. 6.3), L1, lr 1e-3, 5x5 convs of $CH channels:
#        small = 2 hidden layers (3 convs) | large1 = 3 hidden (4 convs) | large2 = 6 hidden (7 convs)
#
# usage: tools/kpcn-train/experiments.sh STORE.kps OUTDIR [NOISY.exr,REF.exr ...]
#   Validation pairs: the arguments after OUTDIR, or (none given) VAL_STORE=VAL.kps
#   (kpcn-train --val-store: the full renders a validation store was cut from); one is required.
# environment (defaults in brackets):
#   KPCN_TRAIN   path of kpcn-train          [build/tools/kpcn-train/kpcn-train]
#   MINUTES      wall-clock budget per run   [10]
#   THREADS      threads per run             [0 = all]
#   BATCH PATCH  batch size, patch side      [16, 64]
#   CH K         depth experiment: channels, prediction window K  [32, 11]
#   PRESET       architecture of experiment A [cpu]
#   ARCH_A       explicit architecture options for experiment A instead of PRESET, e.g.
#                "--preset paper --layers 3 --channels 16 --conv 3 --kernel 5" (word-split)
#   VAL_EVERY    validation interval (iterations) [50]
#   DECAY_EVERY  lr x0.96 every N iterations [1000]
#   SEED         [1]
#   ONLY         "A", "B" or "" (both)
# Outputs in OUTDIR: <run>/model.safetensors(.csv,.png,.ckpt), A_*.png, B_*.png, summary.csv.
# Re-running skips runs whose model exists (delete a run folder to redo it).
set -euo pipefail
here=$(cd "$(dirname "$0")/../.." && pwd)
[ $# -ge 2 ] || { sed -n 2,22p "$0"; exit 2; }
store=$1
out=$2
shift 2
bin=${KPCN_TRAIN:-$here/build/tools/kpcn-train/kpcn-train}
[ -x "$bin" ] || { echo "experiments.sh: $bin not found (set KPCN_TRAIN)" >&2; exit 1; }
[ -f "$store" ] || { echo "experiments.sh: patch store '$store' not found" >&2; exit 1; }
MINUTES=${MINUTES:-10} THREADS=${THREADS:-0} BATCH=${BATCH:-16} PATCH=${PATCH:-64}
CH=${CH:-32} K=${K:-11} PRESET=${PRESET:-cpu} VAL_EVERY=${VAL_EVERY:-50}
DECAY_EVERY=${DECAY_EVERY:-1000} SEED=${SEED:-1} ONLY=${ONLY:-}
val=()
# (kpcn-train's --val-from-store, which this used, was replaced by --val-store in session 57)
if [ $# -gt 0 ]; then
  for p in "$@"; do val+=(--val "$p"); done
elif [ -n "${VAL_STORE:-}" ]; then
  val+=(--val-store "$VAL_STORE")
else
  echo "experiments.sh: give validation pairs (NOISY.exr,REF.exr) or VAL_STORE=VAL.kps" >&2
  exit 2
fi
mkdir -p "$out"

# run NAME ARGS... : one equal-budget stage-1 run (iterations bounded only by the time limit)
run() {
  local name=$1
  shift
  mkdir -p "$out/$name"
  if [ -f "$out/$name/model.safetensors" ]; then
    echo "== $name: done already"
    return
  fi
  echo "== $name ($MINUTES min): $*"
  "$bin" --store "$store" -o "$out/$name/model.safetensors" --iters 1000000000 \
    --stage1-iters 1000000000 --time-limit "$MINUTES" --batch "$BATCH" --patch "$PATCH" \
    --threads "$THREADS" --seed "$SEED" --val-every "$VAL_EVERY" --decay-every "$DECAY_EVERY" \
    --log-every 10 "${val[@]}" "$@" 2>&1 | tr '\r' '\n' | grep -v '^\s*$' | grep -v ' left$' || true
  [ -f "$out/$name/model.safetensors" ] || { echo "experiments.sh: run $name failed" >&2; exit 1; }
}

# compare PREFIX TITLE RUN... : loss / val relMSE / val SSIM against elapsed seconds
compare() {
  local prefix=$1 title=$2
  shift 2
  local args=()
  for r in "$@"; do args+=("$r=$out/$r/model.safetensors.csv"); done
  "$bin" --compare "$out/${prefix}_loss.png" --x elapsed_s --y loss --title "$title: training loss" "${args[@]}"
  "$bin" --compare "$out/${prefix}_val_relmse.png" --x elapsed_s --y val_relmse --title "$title: validation relMSE" "${args[@]}"
  "$bin" --compare "$out/${prefix}_val_ssim.png" --x elapsed_s --y val_ssim --title "$title: validation 1-SSIM" "${args[@]}"
}

if [ -z "$ONLY" ] || [ "$ONLY" = A ]; then
  read -r -a arch_a <<< "${ARCH_A:---preset $PRESET}"
  run A_l1_lr1e-3 "${arch_a[@]}" --loss l1 --lr 1e-3
  run A_l2_lr1e-3 "${arch_a[@]}" --loss l2 --lr 1e-3
  run A_l2_lr1e-5 "${arch_a[@]}" --loss l2 --lr 1e-5
  compare A "loss and learning rate" A_l1_lr1e-3 A_l2_lr1e-3 A_l2_lr1e-5
fi
if [ -z "$ONLY" ] || [ "$ONLY" = B ]; then
  for v in small:2 large1:3 large2:6; do
    run "B_${v%%:*}" --preset paper --layers "${v##*:}" --channels "$CH" --conv 5 --kernel "$K" \
      --loss l1 --lr 1e-3
  done
  compare B "depth (conv5-$CH, K=$K)" B_small B_large1 B_large2
fi

# summary: last row of each run (iterations, seconds, last training loss, final validation)
{
  echo "run,iterations,seconds,train_loss,val_relmse,val_ssim,val_psnr"
  for d in "$out"/*/; do
    r=$(basename "$d")
    csv="$d/model.safetensors.csv"
    [ -f "$csv" ] || continue
    awk -F, -v run="$r" 'NR > 1 { if ($4 != "") loss = $4; if ($7 != "") { rel = $7; ss = $8; ps = $9 }
      it = $1; sec = $6 } END { print run "," it "," sec "," loss "," rel "," ss "," ps }' "$csv"
  done
} > "$out/summary.csv"
echo "== summary ($out/summary.csv)"
column -s, -t < "$out/summary.csv"
