#!/bin/sh
# kpcntool --denoise end to end: model, tiles, bf16, baselines, errors.
# usage: test_denoise_cli.sh KPCNTOOL FIXTURE
set -u
T=$1; F=$2
D=$(mktemp -d /tmp/kpcn_dncli_XXXXXX)
trap 'rm -rf "$D"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
"$F" "$D" || fail "fixture"
"$T" "$D/aov.exr" --denoise:model="$D/model.safetensors" -o "$D/out.exr" || fail "kpcn denoise"
[ -s "$D/out.exr" ] || fail "no output"
"$T" "$D/aov.exr" --denoise:model="$D/model.safetensors":tile=16 -o "$D/out_t.exr" || fail "tiled"
# files may differ in header metadata (command history), so compare pixels
"$T" --json "$D/out_t.exr" "$D/out.exr" --l1 >"$D/l1.json" || fail "l1"
grep -Eq '"l1": *0(\.0*)?([,} ]|$)' "$D/l1.json" || fail "tile=16 differs from untiled: $(cat "$D/l1.json")"
"$T" "$D/aov.exr" --denoise:model="$D/model.safetensors":bf16=1 -o "$D/out_b.exr" || fail "bf16"
for m in bilateral nlmeans; do
  "$T" "$D/aov.exr" --denoise:method=$m -o "$D/$m.exr" || fail "$m"
done
# a render without diffuse.*: non-zero exit, the buffer named, no output file
if "$T" "$D/aov_nodiffuse.exr" --denoise:model="$D/model.safetensors" -o "$D/bad.exr" 2>"$D/err"; then
  fail "missing diffuse accepted"
fi
grep -q diffuse "$D/err" || fail "error does not name diffuse: $(cat "$D/err")"
[ ! -e "$D/bad.exr" ] || fail "partial output written"
if "$T" "$D/aov.exr" --denoise:method=median -o "$D/bad.exr" 2>"$D/err"; then fail "bad method"; fi
grep -q median "$D/err" || fail "error does not name the method"
echo "test_denoise_cli: all passed"
