#!/bin/sh
# tools/rule56_run.sh: the training command is rule 56's as docs/training-log.md wrote it (session
# 46), --resume is added once a checkpoint exists and --time-limit with --minutes, the verdict
# applies the rule's bounds, and bad calls are refused before anything is made.
# usage: test_rule56_run.sh SCRIPT KPCN_BIN
set -u
S=$1; B=$2
D=$(mktemp -d /tmp/kpcn_r56r_XXXXXX)
trap 'rm -rf "$D"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
mkdir -p "$D/data" && : >"$D/data/pool2.kps"
KPCN_BIN=$B bash "$S" --dry-run "$D/data" "$D/R" >"$D/cmd" 2>"$D/err" || fail "dry run: $(cat "$D/err")"
for want in "--store $D/data/pool2.kps " "-o $D/R/model.safetensors " "--preset cpu " \
  "docs/img/experiments/N_model.safetensors --freeze specular --stage1-iters 0 --loss l1 --loss2 rell1-sg --lr 1e-4 --decay-every 500 --seed 56 --threads 2 --iters 12000 --val-every 250 --ckpt-every 250 " \
  "--val $D/data/fp16.exr,$D/data/td/dataset/v1/renders/textures/v000_ref4096spp.exr " \
  "diffuse-interreflection/v000_16spp.exr,$D/data/td/dataset/v1/renders/diffuse-interreflection/v000_ref4096spp.exr " \
  "room-202-0/v000_16spp.exr," "room-202-1/v000_ref1024spp.exr"; do
  grep -qF -- "$want" "$D/cmd" || fail "the command lacks '$want': $(cat "$D/cmd")"
done
[ "$(grep -o -- '--val ' "$D/cmd" | wc -l)" -eq 4 ] || fail "expected four --val pairs"
grep -q -- '--resume\|--time-limit' "$D/cmd" && fail "a first call resumes or has a time limit"
: >"$D/R/model.safetensors.ckpt" # kpcn-train writes its checkpoint beside -o
KPCN_BIN=$B bash "$S" --minutes 40 --dry-run "$D/data" "$D/R" >"$D/cmd2" || fail "second dry run"
grep -q -- '--time-limit 40 --resume' "$D/cmd2" || fail "no --time-limit 40 --resume: $(cat "$D/cmd2")"
[ ! -e "$D/data/fp16.exr" ] || fail "--dry-run rendered"
# the verdict, on made-up judgements (N as judged on the AVX2 host, session 47)
j() { printf '{"textures": %s, "below_noisy": 13.2, "dprime": %s, "val32": %s, "di": %s}\n' "$@"; }
j 2.0009e-4 8.8974e-4 1.09756e-3 5.4901e-4 >"$D/N.json"
v() { j "$@" >"$D/R.json" && bash "$S" --verdict "$D/N.json" "$D/R.json" | tail -n 1; }
v 1.30e-4 8.80e-4 1.09e-3 5.49e-4 | grep -q 'target .* is reached; .* within .* R ships$' || fail "target case"
v 1.85e-4 8.90e-4 1.1031e-3 5.49e-4 | grep -q 'keeps moving .* outside .* does not ship$' || fail "val32 +0.5 % case"
v 1.85e-4 8.90e-4 1.09e-3 5.546e-4 | grep -q 'outside .* does not ship$' || fail "DI +1 % case"
v 1.95e-4 8.80e-4 1.09e-3 5.49e-4 | grep -q 'did not move .* within .* does not ship$' || fail "1.95e-4 case"
v 1.85e-4 8.9418e-4 1.1030e-3 5.5449e-4 | grep -q 'keeps moving .* within .* R ships$' || fail "at the bounds"
# refusals: usage (2), no store or no binaries (1); none creates OUT
bash "$S" "$D/data" 2>/dev/null; [ $? -eq 2 ] || fail "one argument: expected exit 2"
KPCN_BIN=$B bash "$S" "$D/none" "$D/O1" 2>"$D/e1"; [ $? -eq 1 ] || fail "no store: expected exit 1"
grep -q "has not finished" "$D/e1" || fail "no store: message '$(cat "$D/e1")'"
KPCN_BIN=$D/nothing bash "$S" "$D/data" "$D/O2" 2>"$D/e2"; [ $? -eq 1 ] || fail "no binaries: expected exit 1"
KPCN_BIN=$B bash "$S" --minutes x "$D/data" "$D/O3" 2>/dev/null; [ $? -eq 1 ] || fail "--minutes x: expected exit 1"
[ ! -e "$D/O1" ] && [ ! -e "$D/O2" ] && [ ! -e "$D/O3" ] || fail "a refused call created OUT"
echo "rule56_run: rule 56's command, resume, time limit and verdict as written; refusals clean"
