#!/bin/sh
# kpcntool --denoise end to end: model (== the C API), tiles, bf16 (close to fp32), baselines, errors.
# usage: test_denoise_cli.sh KPCNTOOL FIXTURE
set -u
T=$1; F=$2
D=$(mktemp -d /tmp/kpcn_dncli_XXXXXX)
trap 'rm -rf "$D"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
"$F" "$D" || fail "fixture"
"$T" "$D/aov.exr" --denoise:model="$D/model.safetensors" -o "$D/out.exr" || fail "kpcn denoise"
[ -s "$D/out.exr" ] || fail "no output"
# the KPCN through kpcntool equals the C API's result (kpcn_denoise_aov, written by the fixture
# with 2 threads; measured: 1 and 2 threads give the same pixels) pixel for pixel, and is not
# the input
"$T" --threads 2 "$D/aov.exr" --denoise:model="$D/model.safetensors" -o "$D/out_2.exr" || fail "kpcn, 2 threads"
"$T" --json "$D/out_2.exr" "$D/kpcn_api.exr" --l1 >"$D/api.json" || fail "l1 kpcn"
grep -Eq '"l1": *0(\.0*)?([,} ]|$)' "$D/api.json" || fail "kpcn differs from the C API's: $(cat "$D/api.json")"
"$T" --json "$D/out_2.exr" "$D/aov.exr" --ch R,G,B --l1 >"$D/api_in.json" || fail "l1 kpcn vs input"
grep -Eq '"l1": *0(\.0*)?([,} ]|$)' "$D/api_in.json" && fail "kpcn returned its input"
"$T" "$D/aov.exr" --denoise:model="$D/model.safetensors":tile=16 -o "$D/out_t.exr" || fail "tiled"
# files may differ in header metadata (command history), so compare pixels
"$T" --json "$D/out_t.exr" "$D/out.exr" --l1 >"$D/l1.json" || fail "l1"
grep -Eq '"l1": *0(\.0*)?([,} ]|$)' "$D/l1.json" || fail "tile=16 differs from untiled: $(cat "$D/l1.json")"
# a tile below half the model's overlap would cost over 25 times the untiled work (tile=1 of the
# shipped model ran for minutes on a 16x16 image): refused, naming the bound, nothing written
if "$T" "$D/aov.exr" --denoise:model="$D/model.safetensors":tile=1 -o "$D/out_1.exr" 2>"$D/err"; then
  fail "tile=1 accepted"
fi
grep -q "tile 1 would split this [0-9]*x[0-9]* image into tiles whose padded areas .* more than 25 times the untiled work" "$D/err" ||
  fail "tile=1: $(cat "$D/err")"
[ ! -e "$D/out_1.exr" ] || fail "tile=1 wrote an output"
# ... but the padding reaches only as far as the image, so a tile as large as the image is one
# piece, whatever its size (tile=1 on a 1x1 image), and a small tile on a small image costs
# what its clipped padding costs (session 59: tile=15 was refused on 16x16)
oiiotool "$D/aov.exr" --cut 3,4,3,4 -o "$D/aov1.exr" || fail "cut 1x1"
"$T" "$D/aov1.exr" --denoise:model="$D/model.safetensors":tile=1 -o "$D/out1.exr" ||
  fail "tile=1 on a 1x1 image refused"
# bf16 needs AVX-512 (oneDNN 2.6); elsewhere (or under ONEDNN_MAX_CPU_ISA=AVX2) it is refused
# with a message and no output file
bf16=yes
grep -qw avx512f /proc/cpuinfo || bf16=no
case "${ONEDNN_MAX_CPU_ISA:-}" in SSE* | sse* | AVX | avx | AVX2* | avx2*) bf16=no ;; esac
if [ $bf16 = yes ]; then
  "$T" "$D/aov.exr" --denoise:model="$D/model.safetensors":bf16=1 -o "$D/out_b.exr" || fail "bf16"
  # close to f32 but not equal (it ran in bf16): relMSE (eps 0.01) against the f32 result
  # measured 1.06e-9 (rms relative difference 3.3e-5); bound rms 1e-4 (3x), i.e. relMSE 1e-8
  "$T" --json "$D/out_b.exr" "$D/out.exr" --relmse >"$D/b.json" || fail "relmse bf16"
  awk -F'[:,}]' '{ v = $2 + 0; exit !(v > 0 && v <= 1e-8) }' "$D/b.json" ||
    fail "bf16 not within rms 1e-4 of f32 (or equal to it): $(cat "$D/b.json")"
else
  "$T" "$D/aov.exr" --denoise:model="$D/model.safetensors":bf16=1 -o "$D/out_b.exr" 2>"$D/b.err" &&
    fail "bf16 accepted without AVX-512"
  grep -q "bf16 is not available on this CPU" "$D/b.err" || fail "bf16 refusal unclear: $(cat "$D/b.err")"
  [ -e "$D/out_b.exr" ] && fail "bf16 refusal left an output file"
fi
# self-ensemble: differs from the plain output, equals a mirrored input's result mirrored
"$T" "$D/aov.exr" --denoise:model="$D/model.safetensors":ensemble=8 -o "$D/out_e.exr" || fail "ensemble"
"$T" "$D/aov.exr" --mirror --denoise:model="$D/model.safetensors":ensemble=8 --mirror \
  -o "$D/out_em.exr" || fail "ensemble of the mirrored input"
"$T" --json "$D/out_em.exr" "$D/out_e.exr" --relmse >"$D/em.json" || fail "relmse"
grep -Eq '"relmse": *([0-9.]+e-(1[0-9]|[2-9][0-9])|0)([,} ]|$)' "$D/em.json" ||
  fail "ensemble not equivariant to a mirror: $(cat "$D/em.json")"
"$T" --json "$D/out_e.exr" "$D/out.exr" --relmse >"$D/ep.json" || fail "relmse"
grep -Eq '"relmse": *0(\.0*)?([,} ]|$)' "$D/ep.json" && fail "ensemble equals the plain output"
# exposure: the fixture's model records none, so the default (auto) is the input as
# rendered (off); a fixed exposure changes the result; bad values are named
"$T" "$D/aov.exr" --denoise:model="$D/model.safetensors":exposure=off -o "$D/out_xo.exr" || fail "exposure=off"
"$T" --json "$D/out_xo.exr" "$D/out.exr" --l1 >"$D/xo.json" || fail "l1"
grep -Eq '"l1": *0(\.0*)?([,} ]|$)' "$D/xo.json" || fail "exposure=off differs from auto: $(cat "$D/xo.json")"
"$T" "$D/aov.exr" --denoise:model="$D/model.safetensors":exposure=0.05 -o "$D/out_x5.exr" || fail "exposure=0.05"
"$T" --json "$D/out_x5.exr" "$D/out.exr" --l1 >"$D/x5.json" || fail "l1"
grep -Eq '"l1": *0(\.0*)?([,} ]|$)' "$D/x5.json" && fail "exposure=0.05 equals the input as rendered"
grep -aq 'kpcn:exposureScale' "$D/out_x5.exr" || fail "the output header records no exposure scale"
# --exposure reports the statistic and leaves the stack (the image is still written)
"$T" "$D/aov.exr" --exposure --json -o "$D/same.exr" >"$D/ex.json" || fail "--exposure"
grep -Eq '"exposure": *[0-9.]+(e-?[0-9]+)?[,}]' "$D/ex.json" || fail "no exposure: $(cat "$D/ex.json")"
[ -s "$D/same.exr" ] || fail "--exposure consumed the image"
"$T" "$D/aov.exr" --ch R,G,B --exposure 2>"$D/err" && fail "--exposure without diffuse accepted"
grep -q diffuse "$D/err" || fail "--exposure error does not name diffuse: $(cat "$D/err")"
for bad in -1 0 nan inf abc 2,1 1e40; do
  if "$T" "$D/aov.exr" --denoise:model="$D/model.safetensors":exposure=$bad -o "$D/bad.exr" 2>"$D/err"; then
    fail "exposure=$bad accepted"
  fi
  grep -q exposure "$D/err" || fail "error does not name exposure: $(cat "$D/err")"
  [ ! -e "$D/bad.exr" ] || fail "partial output written (exposure=$bad)"
done
# firefly: the default is ratio 4 (explicit 4 == default bit for bit), off is accepted, bad
# ratios are named with no output file
"$T" "$D/aov.exr" --denoise:model="$D/model.safetensors":firefly=4 -o "$D/out_f4.exr" || fail "firefly=4"
"$T" "$D/out_f4.exr" "$D/out.exr" --l1 --json >"$D/f4.json" || fail "compare firefly=4"
grep -Eq '"l1": *0(\.0*)?([,} ]|$)' "$D/f4.json" || fail "firefly=4 differs from the default: $(cat "$D/f4.json")"
"$T" "$D/aov.exr" --denoise:model="$D/model.safetensors":firefly=off -o "$D/out_foff.exr" || fail "firefly=off"
for bad in 0.5 -1 0 nan abc; do
  if "$T" "$D/aov.exr" --denoise:model="$D/model.safetensors":firefly=$bad -o "$D/bad.exr" 2>"$D/err"; then
    fail "firefly=$bad accepted"
  fi
  grep -q firefly "$D/err" || fail "error does not name firefly: $(cat "$D/err")"
  [ ! -e "$D/bad.exr" ] || fail "partial output written (firefly=$bad)"
done
if "$T" "$D/aov.exr" --denoise:model="$D/model.safetensors":ensemble=3 -o "$D/bad.exr" 2>"$D/err"; then
  fail "ensemble=3 accepted"
fi
grep -q ensemble "$D/err" || fail "error does not name ensemble: $(cat "$D/err")"
[ ! -e "$D/bad.exr" ] || fail "partial output written"
# the baselines through kpcntool equal the C API's results (written by the fixture), pixel for
# pixel, and are not the input
for m in bilateral nlmeans; do
  "$T" "$D/aov.exr" --denoise:method=$m -o "$D/$m.exr" || fail "$m"
  "$T" --json "$D/$m.exr" "$D/${m}_api.exr" --l1 >"$D/$m.json" || fail "l1 $m"
  grep -Eq '"l1": *0(\.0*)?([,} ]|$)' "$D/$m.json" || fail "$m differs from the C API's: $(cat "$D/$m.json")"
  "$T" --json "$D/$m.exr" "$D/aov.exr" --ch R,G,B --l1 >"$D/${m}_in.json" || fail "l1 $m vs input"
  grep -Eq '"l1": *0(\.0*)?([,} ]|$)' "$D/${m}_in.json" && fail "$m returned its input"
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
