#!/usr/bin/env bash
# Trains a model to ship and writes testdata/models/README.md from what actually ran
# (command line, dataset, time, hardware, final validation metrics), so the README is a
# record produced by the pipeline. It trained the shipped models of sessions 2-23; the model
# shipped now (R) came from tools/rule56_run.sh, whose README was written from its log, so a
# run of this script replaces that README with its own.
#
# usage: tools/kpcn-train/ship_model.sh STORE.kps [NOISY.exr,REF.exr ...]
#   Validation: the pairs given, or (none given) VAL_STORE=VAL.kps (kpcn-train --val-store: the
#   full renders a validation store was cut from); one of the two is required.
# environment (defaults): MINUTES (60) training budget, PRESET (cpu), ITERS (none: sized to fit
#   MINUTES from a 20-iteration speed probe, below), STAGE1_FRACTION (0.6 of the iterations, or of the
#   budget when time-limited: see below), LOSS2 (l1), THREADS (0), SEED (1),
#   NAME (kpcn-$PRESET), DATASET_RECIPE (free text: how the store was made), KPCN_TRAIN,
#   LR (1e-3), LR2 (stage-2 lr, default LR), DECAY_EVERY (iterations per x0.96, default
#   iters/20), TIME_LIMIT (minutes, none), KEEP_BEST (1: ship the model of the validation
#   with the lowest relMSE instead of the last one; needs validation pairs), INIT (a model to
#   fine-tune: kpcn-train --init), SHIP_IF_BELOW (a validation relMSE: replace the shipped
#   model only if this run's shipped validation relMSE is lower, e.g. the current model's),
#   INIT_NOTE (README text on where INIT came from; default: the previously shipped model),
#   README_ONLY (1: train nothing, copy nothing; rewrite README.md from the finished run in
#   WORK, e.g. after editing INIT_NOTE; same environment as the run), NO_TRAIN (1: the run in
#   WORK is finished: select, copy and write the README without training), SWA_FROM (a fraction,
#   e.g. 0.5: keep every checkpoint (--snapshots WORK/snapshots, or SNAPSHOT_DIR), average the
#   weights of those from that fraction of the run on (kpcn-train --average), score the
#   average and the KEEP_BEST/last candidate on the validation pairs with kpcntool (mean
#   relMSE, R,G,B: the trainer's own validation figure) and ship the lower; needs pairs;
#   SNAPSHOT_NOTE: README text on how the snapshots were kept, if not by --snapshots),
#   BEST_BY (mean: default; geomean: the best model, the SWA comparison and SHIP_IF_BELOW use
#   the geometric mean of the per-pair relMSE instead, kpcn-train --best-by), WIDEN (with
#   INIT: widen it to this many hidden channels first, kpcn-train --widen), BF16 (1: mixed-
#   precision training, kpcn-train --bf16), KPA_PASSES (apply the predicted kernels this many
#   times, kpcn-train --kpa-passes; with INIT it converts the model), SOURCE_WEIGHT=1 (predict
#   a per-pixel source weight too, kpcn-train --source-weight; with INIT it adds it),
#   SOURCE_LR_SCALE (its learning-rate multiple, kpcn-train --source-lr-scale), FIREFLY (a
#   ratio: bound diffuse fireflies in the training patches, kpcn-train --firefly), EPS (the
#   albedo epsilon of the diffuse demodulation, kpcn-train --eps; with INIT it changes the
#   model's), FREEZE (diffuse or specular: with INIT, that branch keeps INIT's weights bit for
#   bit, kpcn-train --freeze), KPCNTOOL (the kpcntool that scores SWA candidates, default
#   build/tools/kpcntool/kpcntool).
# With a time budget the iteration count is unknown in advance, so the script first measures
# the speed (20 iterations) and sets --iters to fit MINUTES, --stage1-iters to STAGE1_FRACTION.
# Resumable: if the run is interrupted, re-running continues from its checkpoint.
set -euo pipefail
here=$(cd "$(dirname "$0")/../.." && pwd)
[ $# -ge 1 ] || { sed -n 2,38p "$0"; exit 2; }
store=$1
shift
bin=${KPCN_TRAIN:-$here/build/tools/kpcn-train/kpcn-train}
[ -x "$bin" ] || { echo "ship_model.sh: $bin not found (set KPCN_TRAIN)" >&2; exit 1; }
MINUTES=${MINUTES:-60} PRESET=${PRESET:-cpu} LOSS2=${LOSS2:-l1} THREADS=${THREADS:-0}
SEED=${SEED:-1} NAME=${NAME:-kpcn-$PRESET} FRAC=${STAGE1_FRACTION:-0.6}
outdir=$here/testdata/models
work=${WORK:-$here/out/ship-$NAME} # /out/ is git-ignored
val=()
# (kpcn-train's --val-from-store, which this used, was replaced by --val-store in session 57)
if [ $# -gt 0 ]; then
  for p in "$@"; do val+=(--val "$p"); done
elif [ -n "${VAL_STORE:-}" ]; then
  val+=(--val-store "$VAL_STORE")
else
  echo "ship_model.sh: give validation pairs (NOISY.exr,REF.exr) or VAL_STORE=VAL.kps" >&2
  exit 2
fi
mkdir -p "$outdir" "$work"

if [ -n "${ITERS:-}" ]; then
  iters=$ITERS
elif [ -f "$work/iters" ]; then
  iters=$(cat "$work/iters")
else
  # speed probe: 20 iterations of the same configuration, no outputs kept
  start=$(date +%s.%N)
  "$bin" --store "$store" -o "$work/probe.safetensors" --preset "$PRESET" --iters 20 \
    --stage1-iters 10 --threads "$THREADS" --seed "$SEED" --csv '' --plot '' --quiet \
    $([ "${BF16:-0}" = 1 ] && echo --bf16)
  end=$(date +%s.%N)
  rm -f "$work"/probe.*
  iters=$(awk -v s="$start" -v e="$end" -v m="$MINUTES" 'BEGIN { r = 20 / (e - s); n = int(r * m * 60 * 0.9); print (n < 20 ? 20 : n) }')
  echo "$iters" > "$work/iters"
fi
stage1=$(awk -v n="$iters" -v f="$FRAC" 'BEGIN { print int(n * f) }')
LR=${LR:-1e-3} DECAY_EVERY=${DECAY_EVERY:-$((iters / 20 > 0 ? iters / 20 : 1))}
args=(--store "$store" -o "$work/model.safetensors" --preset "$PRESET" --iters "$iters"
  --stage1-iters "$stage1" --loss l1 --loss2 "$LOSS2" --lr "$LR" --decay-every "$DECAY_EVERY"
  --threads "$THREADS" --seed "$SEED" --val-every $((iters / 28 > 0 ? iters / 28 : 1))
  --ckpt-every 100 "${val[@]}")
BEST_BY=${BEST_BY:-mean}
case $BEST_BY in mean) vcol=7 ;; geomean) vcol=10 ;; *) echo "ship_model.sh: BEST_BY=$BEST_BY is not mean or geomean" >&2; exit 2 ;; esac
[ "$BEST_BY" = geomean ] && args+=(--best-by geomean)
[ -n "${LR2:-}" ] && args+=(--lr2 "$LR2")
[ -n "${INIT:-}" ] && args+=(--init "$INIT")
[ -n "${WIDEN:-}" ] && args+=(--widen "$WIDEN")
[ "${BF16:-0}" = 1 ] && args+=(--bf16)
[ -n "${KPA_PASSES:-}" ] && args+=(--kpa-passes "$KPA_PASSES")
[ "${SOURCE_WEIGHT:-0}" = 1 ] && args+=(--source-weight)
[ -n "${SOURCE_LR_SCALE:-}" ] && args+=(--source-lr-scale "$SOURCE_LR_SCALE")
[ -n "${FIREFLY:-}" ] && args+=(--firefly "$FIREFLY")
[ -n "${EPS:-}" ] && args+=(--eps "$EPS")
[ -n "${FREEZE:-}" ] && args+=(--freeze "$FREEZE")
[ -n "${TIME_LIMIT:-}" ] && args+=(--time-limit "$TIME_LIMIT")
snapdir=${SNAPSHOT_DIR:-$work/snapshots}
[ -n "${SWA_FROM:-}" ] && [ -z "${SNAPSHOT_DIR:-}" ] && args+=(--snapshots "$snapdir")
shipped=$work/model.safetensors
if [ "${KEEP_BEST:-0}" = 1 ]; then
  args+=(--best "$work/best.safetensors")
  shipped=$work/best.safetensors
fi
resume=()
[ -f "$work/model.safetensors.ckpt" ] && resume=(--resume)
if [ "${README_ONLY:-0}" != 1 ] && [ "${NO_TRAIN:-0}" != 1 ]; then
  echo "ship_model.sh: $bin ${args[*]} ${resume[*]}"
  "$bin" "${args[@]}" "${resume[@]}"
fi
col=$([ "${KEEP_BEST:-0}" = 1 ] && echo best || echo last)
got=$(awk -F, -v w="$col" -v c="$vcol" 'NR > 1 && $c != "" { if (w == "last" || b == "" || $c + 0 < b + 0) b = $c } END { print b }' "$work/model.safetensors.csv")
if [ -n "${SWA_FROM:-}" ]; then
  [ $# -gt 0 ] || { echo "ship_model.sh: SWA_FROM needs validation pairs" >&2; exit 2; }
  tool=${KPCNTOOL:-$here/build/tools/kpcntool/kpcntool}
  last_it=$(awk -F, 'NR > 1 { it = $1 } END { print it }' "$work/model.safetensors.csv")
  from=$(awk -v n="$last_it" -v f="$SWA_FROM" 'BEGIN { print int(n * f) }')
  snaps=()
  for f in "$snapdir"/ckpt_*.safetensors; do
    it=$(basename "$f" | tr -dc 0-9)
    [ -n "$it" ] && [ $((10#$it)) -ge "$from" ] && snaps+=("$f")
  done
  [ ${#snaps[@]} -gt 0 ] || { echo "ship_model.sh: no snapshots from iteration $from in $snapdir" >&2; exit 1; }
  if [ "${README_ONLY:-0}" != 1 ] || [ ! -f "$work/swa.score" ]; then
    "$bin" --average "$work/swa.safetensors" "${snaps[@]}"
    score() { # mean (or geometric mean) relMSE (R,G,B) of a model over the validation pairs
      local t; t=$(mktemp -d)
      for p in "${pairs[@]}"; do
        "$tool" "${p%%,*}" --denoise:model="$1" -o "$t/d.exr" >/dev/null
        "$tool" "$t/d.exr" "${p#*,}" --ch R,G,B --relmse --json
      done | sed -n 's/.*"relmse": *\([0-9.eE+-]*\).*/\1/p' |
        awk -v g="$BEST_BY" '{ s += (g == "geomean" ? log($1 > 1e-30 ? $1 : 1e-30) : $1); n++ }
          END { printf "%.9g\n", g == "geomean" ? exp(s / n) : s / n }'
      rm -rf "$t"
    }
    pairs=("$@")
    swa_score=$(score "$work/swa.safetensors")
    echo "ship_model.sh: SWA of ${#snaps[@]} snapshots (iterations >= $from): validation relMSE $swa_score; $col model: $got"
    echo "${#snaps[@]} $from $swa_score" > "$work/swa.score"
  fi
  read -r swa_n swa_from swa_score < "$work/swa.score"
  if awk -v a="$swa_score" -v b="$got" 'BEGIN { exit !(a + 0 < b + 0) }'; then
    shipped=$work/swa.safetensors
    got=$swa_score
  fi
fi
if [ "${README_ONLY:-0}" != 1 ]; then
  if [ -n "${SHIP_IF_BELOW:-}" ]; then
    if ! awk -v g="$got" -v t="$SHIP_IF_BELOW" 'BEGIN { exit !(g != "" && g + 0 < t + 0) }'; then
      echo "ship_model.sh: validation relMSE ${got:-none} is not below $SHIP_IF_BELOW: the shipped model stays; this run is in $work"
      exit 0
    fi
  fi
  cp "$shipped" "$outdir/$NAME.safetensors"
  cp "$work/model.safetensors.png" "$outdir/$NAME-curves.png"
  cp "$work/model.safetensors.csv" "$outdir/$NAME-log.csv"
fi
# validation rows: iteration, mean relMSE, SSIM, PSNR (and the geometric mean when selecting by it)
g=$([ "$BEST_BY" = geomean ] && echo 1 || echo 0)
last=$(awk -F, -v g="$g" 'NR > 1 && $7 != "" { r = $7; s = $8; p = $9; it = $1; q = $10 } END { print it "," r "," s "," p (g ? "," q : "") }' "$work/model.safetensors.csv")
best=$(awk -F, -v c="$vcol" -v g="$g" 'NR > 1 && $c != "" && (v == "" || $c + 0 < v + 0) { v = $c; b = $7; s = $8; p = $9; it = $1; q = $10 } END { print it "," b "," s "," p (g ? "," q : "") }' "$work/model.safetensors.csv")
cols="iter, relMSE, SSIM, PSNR dB$([ "$g" = 1 ] && echo ", geometric-mean relMSE")"
score=$([ "$g" = 1 ] && echo "geometric-mean validation relMSE" || echo "validation relMSE")
done_iters=$(awk -F, 'NR > 1 { it = $1 } END { print it }' "$work/model.safetensors.csv")
secs=$(awk -F, 'NR > 1 { s = $6 } END { print s }' "$work/model.safetensors.csv")
cpu=$(lscpu 2>/dev/null | sed -n 's/^Model name: *//p' | head -1)
{
  echo "# Shipped model: $NAME"
  echo
  echo "Produced by \`tools/kpcn-train/ship_model.sh\` on $(date -u +%Y-%m-%d) (UTC); this file"
  echo "was generated by that script from the run's own log."
  echo
  echo "| | |"
  echo "|---|---|"
  echo "| file | \`$NAME.safetensors\` ($(stat -c %s "$outdir/$NAME.safetensors") bytes) |"
  echo "| preset | $PRESET |"
  echo "| patch store | \`$(basename "$store")\` |"
  echo "| dataset recipe | ${DATASET_RECIPE:-see docs/dataset.md} |"
  [ -n "${INIT:-}" ] && echo "| initialised from | \`$(basename "$INIT")\` (${INIT_NOTE:-the previously shipped model; its own README is in git history}) |"
  [ -n "${WIDEN:-}" ] && echo "| widened | to $WIDEN hidden channels before training (\`kpcn-train --widen\`: same function, new units start with zero outgoing weights) |"
  [ -n "${KPA_PASSES:-}" ] && echo "| kernel passes | $KPA_PASSES (\`kpcn-train --kpa-passes\`: the predicted kernels applied $KPA_PASSES times, each pass on the previous one's result; docs/nn.md) |"
  [ "${SOURCE_WEIGHT:-0}" = 1 ] && echo "| source weights | yes (\`kpcn-train --source-weight\`: a per-pixel weight the first kernel pass renormalises by; docs/nn.md)${SOURCE_LR_SCALE:+, learning at $SOURCE_LR_SCALE× the rate (\`--source-lr-scale\`)} |"
  [ -n "${EPS:-}" ] && echo "| demodulation epsilon | $EPS (\`kpcn-train --eps\`: diffuse / (albedo + $EPS); docs/denoiser.md) |"
  [ -n "${FREEZE:-}" ] && echo "| frozen branch | $FREEZE (\`kpcn-train --freeze\`: kept bit for bit from the initial model; only the other branch trained) |"
  [ "${BF16:-0}" = 1 ] && echo "| precision | bf16 mixed precision (\`kpcn-train --bf16\`: bf16 convolutions, f32 weights, gradients and Adam) |"
  echo "| iterations | $done_iters of $iters planned (stage 1: $stage1, stage-2 loss $LOSS2) |"
  echo "| training time | ${secs} s |"
  echo "| hardware | ${cpu:-unknown CPU}, $(nproc) cores, threads=$THREADS |"
  [ "$BEST_BY" = geomean ] && echo "| selection | by the geometric mean of the per-pair validation relMSE (\`--best-by geomean\`; the relMSE columns below are means) |"
  echo "| last validation ($cols) | $last |"
  if [ -n "${SWA_FROM:-}" ]; then
    [ "${KEEP_BEST:-0}" = 1 ] && echo "| best validation ($cols) | $best |"
    echo "| weight average (SWA) | mean of $swa_n checkpoints, iterations $swa_from to $done_iters ($(basename "$snapdir")/, ${SNAPSHOT_NOTE:-kept by \`--snapshots\`}): $score $swa_score |"
    echo "| shipped | $([ "$shipped" = "$work/swa.safetensors" ] && echo "the weight average (lower validation relMSE)" || echo "the $col model (lower validation relMSE than the average)") |"
  elif [ "${KEEP_BEST:-0}" = 1 ]; then
    echo "| shipped: best validation ($cols) | $best |"
  fi
  echo
  echo "Exact command:"
  echo
  echo '```sh'
  echo "kpcn-train ${args[*]}"
  echo '```'
  if [ -n "${SWA_FROM:-}" ]; then
    echo
    echo "then \`kpcn-train --average swa.safetensors <the $swa_n checkpoints>\` and the validation"
    echo "score of both candidates with \`kpcntool NOISY --denoise:model=M -o d.exr\` +"
    echo "\`kpcntool d.exr REF --ch R,G,B --relmse\` over the same pairs (\`SWA_FROM=$SWA_FROM\`)."
  fi
  echo
  echo "(\`-o\` pointed at a work folder; the script copied the model, its CSV log and the curves"
  echo "plot \`$NAME-curves.png\` here.) Validation images are full held-out renders (see"
  echo "docs/training.md)."
} > "$outdir/README.md"
echo "ship_model.sh: wrote $outdir/$NAME.safetensors and $outdir/README.md"
