#!/bin/sh
# kpcn-train --exposure-range: a copy of a model recording the exposure range of a patch
# store's training images; same weights; bad inputs named, no output file.
# usage: test_train_cli.sh KPCN_TRAIN KPCNTOOL TESTDATA
set -u
K=$1; T=$2; TD=$3
D=$(mktemp -d /tmp/kpcn_trcli_XXXXXX)
trap 'rm -rf "$D"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
N="$TD/dataset/sample_noisy.exr"; M="$TD/models/kpcn-cpu.safetensors"
"$T" "$N" "$TD/dataset/sample_ref.exr" --patches:size=16:count=6:cull=1:out="$D/p.kps" || fail "patches"
"$K" --exposure-range "$D/m.safetensors" "$M" "$D/p.kps" >"$D/log" || fail "exposure-range"
grep -q 'exposure range \[' "$D/log" || fail "no range printed: $(cat "$D/log")"
grep -aq '\\"exposure_range\\":\[' "$D/m.safetensors" || fail "model header records no exposure_range"
# the store's one source is this image, so the range holds its exposure: as rendered, and
# the weights are the model's, so the result is the original model's bit for bit
"$T" "$N" --denoise:model="$D/m.safetensors" -o "$D/a.exr" || fail "denoise with the new model"
"$T" "$N" --denoise:model="$M":exposure=off -o "$D/b.exr" || fail "denoise as rendered"
"$T" --json "$D/a.exr" "$D/b.exr" --l1 >"$D/l1.json" || fail "l1"
grep -Eq '"l1": *0(\.0*)?([,} ]|$)' "$D/l1.json" || fail "new model differs: $(cat "$D/l1.json")"
# bad inputs: a missing store, a store that is no store, a model that is no model
for args in "$M $D/nope.kps" "$M $N" "$N $D/p.kps"; do
  # shellcheck disable=SC2086
  if "$K" --exposure-range "$D/bad.safetensors" $args 2>"$D/err"; then fail "accepted: $args"; fi
  [ -s "$D/err" ] || fail "no error message: $args"
  [ ! -e "$D/bad.safetensors" ] || fail "partial output written: $args"
done
"$K" --exposure-range "$D/bad.safetensors" "$M" 2>"$D/err" && fail "accepted without a store"
grep -q 'expected' "$D/err" || fail "usage error unclear: $(cat "$D/err")"
echo "test_train_cli: ok"
