#!/bin/sh
# kpcn-train --record-exposure: a copy of a model recording the median exposure of a patch
# store's training images; same weights; bad inputs named, no output file. --firefly: bad ratios named.
# usage: test_train_cli.sh KPCN_TRAIN KPCNTOOL TESTDATA
set -u
K=$1; T=$2; TD=$3
D=$(mktemp -d /tmp/kpcn_trcli_XXXXXX)
trap 'rm -rf "$D"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
N="$TD/dataset/sample_noisy.exr"; M="$TD/models/kpcn-cpu.safetensors"
"$T" "$N" "$TD/dataset/sample_ref.exr" --patches:size=16:count=6:cull=1:out="$D/p.kps" || fail "patches"
"$K" --record-exposure "$D/m.safetensors" "$M" "$D/p.kps" >"$D/log" || fail "record-exposure"
E=$(sed -n 's/.*recording exposure \([0-9.e+-]*\)$/\1/p' "$D/log")
[ -n "$E" ] || fail "no exposure printed: $(cat "$D/log")"
grep -aq '\\"exposure\\":' "$D/m.safetensors" || fail "model header records no exposure"
# the store's one source is this image, so the exposure recorded is its own; the weights are
# the model's: by default the new model gives the original's result at that exposure, bit
# for bit
"$T" "$N" --exposure --json >"$D/e.json" || fail "--exposure"
EI=$(sed -n 's/.*"exposure": *\([0-9.eE+-]*\).*/\1/p' "$D/e.json")
[ -n "$EI" ] || fail "no exposure in $(cat "$D/e.json")"
awk -v a="$E" -v b="$EI" 'BEGIN { d = a - b; if (d < 0) d = -d; exit !(b > 0 && d <= 1e-6 * b) }' ||
  fail "recorded exposure $E is not the image's own $EI"
"$T" "$N" --denoise:model="$D/m.safetensors" -o "$D/a.exr" || fail "denoise with the new model"
"$T" "$N" --denoise:model="$M":exposure="$E" -o "$D/b.exr" || fail "denoise at exposure $E"
"$T" --json "$D/a.exr" "$D/b.exr" --l1 >"$D/l1.json" || fail "l1"
grep -Eq '"l1": *0(\.0*)?([,} ]|$)' "$D/l1.json" || fail "new model differs: $(cat "$D/l1.json")"
# bad inputs: a missing store, a store that is no store, a model that is no model
for args in "$M $D/nope.kps" "$M $N" "$N $D/p.kps"; do
  # shellcheck disable=SC2086
  if "$K" --record-exposure "$D/bad.safetensors" $args 2>"$D/err"; then fail "accepted: $args"; fi
  # the message names the file at fault (the last argument for a bad store, else the model)
  case "$args" in "$M $D/nope.kps") want="$D/nope.kps" ;; "$M $N") want="$N" ;; *) want="$N" ;; esac
  grep -qF -- "$want" "$D/err" || fail "error does not name '$want': $(cat "$D/err")"
  [ ! -e "$D/bad.safetensors" ] || fail "partial output written: $args"
done
"$K" --record-exposure "$D/bad.safetensors" "$M" 2>"$D/err" && fail "accepted without a store"
grep -q 'expected' "$D/err" || fail "usage error unclear: $(cat "$D/err")"
# --firefly: a ratio below 1 or no number is refused naming the option, nothing is written
for bad in 0.5 abc; do
  if "$K" --store "$D/p.kps" -o "$D/f.safetensors" --iters 1 --firefly $bad 2>"$D/err"; then
    fail "--firefly $bad accepted"
  fi
  grep -q firefly "$D/err" || fail "--firefly error unclear: $(cat "$D/err")"
  [ ! -e "$D/f.safetensors" ] || fail "output written for --firefly $bad"
done
# usage mistakes are refused before anything is read or written (exit 2), naming the option
# (--dilations with too many values or junk, --ssim-window without an SSIM loss or even,
# shape options an --init model does not have)
bad_usage() {
  pat=$1; shift
  "$K" --store "$D/p.kps" -o "$D/u.safetensors" --iters 1 "$@" 2>"$D/err"
  rc=$?
  [ $rc -eq 2 ] || fail "exit $rc (want 2) for: $* ($(cat "$D/err"))"
  grep -qF -- "$pat" "$D/err" || fail "message lacks '$pat' for: $*: $(cat "$D/err")"
  [ ! -e "$D/u.safetensors" ] && [ ! -e "$D/u.safetensors.csv" ] || fail "output written for: $*"
}
bad_usage "at most 3 positive integers" --preset tiny --dilations 1,2,3,4
bad_usage "at most 3 positive integers" --preset tiny --dilations 1,2,1x
bad_usage "--ssim-window has no effect" --ssim-window 7
bad_usage "the window must be odd" --loss2 ssim --ssim-window 4
bad_usage "--layers asks for 5 hidden layers, the --init model" --init "$M" --layers 5
bad_usage "--preset asks for" --init "$M" --preset tiny
bad_usage "--average must be the first argument" --average "$M"
# an output that would overwrite the patch store is refused; the store is intact
if "$K" --store "$D/p.kps" -o "$D/c.safetensors" --iters 1 --csv "$D/p.kps" 2>"$D/err"; then
  fail "--csv over the store accepted"
fi
grep -q "are the same file" "$D/err" || fail "store clash unclear: $(cat "$D/err")"
"$T" "$N" "$TD/dataset/sample_ref.exr" --patches:size=16:count=6:cull=1:out="$D/p2.kps" || fail "patches 2"
cmp -s "$D/p.kps" "$D/p2.kps" || fail "the store was changed"
echo "test_train_cli: ok"
