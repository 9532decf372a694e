#!/bin/sh
# kpcntool --kernels: the exported kernels of both branches redo --denoise's result
# (kernels_check.py), tiles do not change them, and bad requests are refused by name with no
# output file.
# tools/show_kernels.py's footprints, recombined at a pixel, give that pixel's denoised value.
# The fixture's model has one kernel pass; the shipped model (two) is checked on a small render.
# usage: test_kernels_cli.sh KPCNTOOL FIXTURE KERNELS_CHECK_PY SHOW_KERNELS_PY TESTDATA
set -u
T=$1; F=$2; CHECK=$3; SHOW=$4; TD=$5
D=$(mktemp -d /tmp/kpcn_kcli_XXXXXX)
trap 'rm -rf "$D"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
"$F" "$D" || fail "fixture"
M="$D/model.safetensors"
"$T" "$D/aov.exr" --denoise:model="$M" -o "$D/out.exr" || fail "denoise"
"$T" "$D/aov.exr" --kernels:model="$M" -o "$D/kd.exr" || fail "kernels (diffuse, the default)"
"$T" "$D/aov.exr" --kernels:model="$M":branch=specular -o "$D/ks.exr" || fail "kernels specular"
/usr/bin/python3 "$CHECK" "$D/aov.exr" "$D/kd.exr" "$D/ks.exr" "$D/out.exr" || fail "kernels_check"
# the specular files swapped in for the diffuse must not pass (the check can fail)
/usr/bin/python3 "$CHECK" "$D/aov.exr" "$D/ks.exr" "$D/ks.exr" "$D/out.exr" 2>/dev/null &&
  fail "kernels_check accepted the wrong branch"
"$T" "$D/aov.exr" --kernels:model="$M":tile=16 -o "$D/kd_t.exr" || fail "kernels tiled"
"$T" --json "$D/kd_t.exr" "$D/kd.exr" --l1 >"$D/l1.json" || fail "l1"
grep -Eq '"l1": *0(\.0*)?([,} ]|$)' "$D/l1.json" || fail "tile=16 kernels differ: $(cat "$D/l1.json")"
# the shipped model: two passes
S="$TD/dataset/sample_noisy.exr" N="$TD/models/kpcn-cpu.safetensors"
"$T" "$S" --denoise:model="$N" -o "$D/n_out.exr" || fail "denoise (shipped model)"
"$T" "$S" --kernels:model="$N" -o "$D/n_kd.exr" || fail "kernels diffuse (shipped model)"
"$T" "$S" --kernels:model="$N":branch=specular -o "$D/n_ks.exr" || fail "kernels specular (shipped)"
/usr/bin/python3 "$CHECK" "$S" "$D/n_kd.exr" "$D/n_ks.exr" "$D/n_out.exr" || fail "kernels_check (shipped)"
# show_kernels.py: each pixel's footprint (pulled back through every pass) recombined from both
# branches is the denoised pixel; a corner pixel exercises the clamped reads
for run in fixture:0,0 fixture:7,5 shipped:0,0 shipped:20,17; do
  px=${run#*:}
  if [ "${run%%:*}" = fixture ]; then p=""; aov="$D/aov.exr"; else p="n_"; aov="$S"; fi
  /usr/bin/python3 "$SHOW" "$D/${p}kd.exr" $px --json >"$D/sd.json" || fail "show_kernels diffuse $run"
  /usr/bin/python3 "$SHOW" "$D/${p}ks.exr" $px --json >"$D/ss.json" || fail "show_kernels specular $run"
  /usr/bin/python3 - "$D" "$px" "$D/${p}kd.exr" "$aov" "$D/${p}out.exr" <<'PY' || fail "show_kernels footprint at $run is not the denoised pixel"
import json, sys
import numpy as np, OpenImageIO as oiio
d, px, kernels, aov, out = sys.argv[1:6]
x, y = (int(v) for v in px.split(","))
(dr,), (sr,) = json.load(open(d + "/sd.json")), json.load(open(d + "/ss.json"))
spec = oiio.ImageBuf(kernels).spec()
eps, scale = spec.getattribute("kpcn:eps"), spec.getattribute("kpcn:exposureScale")
def pixel(path, names):
    b = oiio.ImageBuf(path); p = b.get_pixels(oiio.FLOAT); n = list(b.spec().channelnames)
    return np.array([p[y, x, n.index(c)] for c in names], np.float64)
alb, den = pixel(aov, ["albedo.R", "albedo.G", "albedo.B"]), pixel(out, "RGB")
got = (np.array(dr["result"]) * (alb + eps) + np.expm1(sr["result"])) / scale
err = (np.abs(got - den) / (1e-3 + np.abs(den))).max()
print("show_kernels at %s (%d passes): footprint sums %.6f / %.6f, recombined vs denoised: "
      "max rel err %.3g" % (px, dr["passes"], dr["footprint_sum"], sr["footprint_sum"], err))
sys.exit(0 if err < 1e-4 and abs(dr["footprint_sum"] - 1) < 1e-5 else 1)
PY
done
/usr/bin/python3 "$SHOW" "$D/kd.exr" 1,2 3,4 -o "$D/fig.png" >/dev/null || fail "show_kernels -o"
[ -s "$D/fig.png" ] || fail "show_kernels wrote no PNG"
/usr/bin/python3 "$SHOW" "$D/aov.exr" 1,1 2>"$D/err" && fail "show_kernels took an AOV file"
grep -q "no kpcntool --kernels file" "$D/err" || fail "show_kernels error unclear: $(cat "$D/err")"
/usr/bin/python3 "$SHOW" "$D/kd.exr" 1000,1 2>"$D/err" && fail "show_kernels took a pixel outside"
grep -q "outside" "$D/err" || fail "show_kernels error unclear: $(cat "$D/err")"
bad() { # EXPECTED-WORD ARGS...: refused, the word in the message, no output file
  word=$1; shift
  "$T" "$@" -o "$D/bad.exr" 2>"$D/err" && fail "accepted: $*"
  grep -q "$word" "$D/err" || fail "error for '$*' does not name $word: $(cat "$D/err")"
  [ ! -e "$D/bad.exr" ] || fail "partial output written: $*"
}
bad model "$D/aov.exr" --kernels
bad branch "$D/aov.exr" --kernels:model="$M":branch=albedo
bad ensemble "$D/aov.exr" --kernels:model="$M":ensemble=2
bad method "$D/aov.exr" --kernels:model="$M":method=nlmeans
bad diffuse "$D/aov_nodiffuse.exr" --kernels:model="$M"
bad nope.safetensors "$D/aov.exr" --kernels:model="$D/nope.safetensors"
echo "test_kernels_cli: all passed"
