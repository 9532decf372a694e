# kpcntool metrics vs the numpy/scikit-image values in testdata/metrics/reference.json
# (the cornell pair), JSON output, chaining, threads.
. "$(dirname "$0")/lib.sh"
REFJSON=$TD/metrics/reference.json
for disp in linear srgb; do
  run_ok "$NOISY" "$REF" --l1:display=$disp --mse:display=$disp --relmse:display=$disp \
    --rell1:display=$disp --psnr:display=$disp --ssim:display=$disp --json
  cp out.txt got_$disp.json
  for m in l1 mse relmse rell1 psnr ssim; do
    want=$($PY -c 'import json,sys; d=json.load(open(sys.argv[1]))
print(repr([c for c in d["cases"] if c["name"]==sys.argv[2]][0]["values"][sys.argv[3]]))' \
      "$REFJSON" "cornell_$disp" $m)
    got=$(json_get got_$disp.json $m)
    # relative 1e-8: the recorded values agree to ~1e-15 (SSIM in sRGB ~2e-10)
    if near_rel "$got" "$want" 1e-8; then pass "$disp $m $got ~ $want"; else fail "$disp $m $got != $want"; fi
  done
done
# The exact command of the issue.
run_ok "$NOISY" "$REF" --ssim --relmse --json
$PY -c 'import json,sys; d=json.load(open(sys.argv[1])); assert set(d)=={"ssim","relmse"}' out.txt \
  && pass "json has ssim, relmse" || fail "json keys: $(cat out.txt)"
# Human-readable form prints name: value.
run_ok "$NOISY" "$REF" --relmse
grep -q '^relmse: *0.0106230' out.txt && pass "human readable" || fail "human: $(cat out.txt)"
# Chaining: metrics leave the stack alone; a later pair is compared too; keys stay unique.
run_ok "$NOISY" "$REF" --relmse "$REF" "$REF" --relmse --ssim:channels=G --json
cp out.txt chain.json
near "$(json_get chain.json relmse)" 0.010623011681784552 1e-7 && near "$(json_get chain.json relmse_2)" 0 0 \
  && near "$(json_get chain.json ssim)" 1 1e-12 && pass "chaining" || fail "chaining: $(cat chain.json)"
# An explicit list is compared as given, past the AOV default's R,G,B: relMSE is the mean
# over the channels, so R,G,B,Z's is (3 RGB + Z) / 4 (session 58: an explicit list holding
# R,G,B was cut back to them)
AOVN="$TD/dataset/sample_noisy.exr" AOVR="$TD/dataset/sample_ref.exr"
run_ok "$AOVN" "$AOVR" --relmse:channels=R,G,B,Z --relmse --relmse:channels=Z --json
cp out.txt list.json
want=$($PY -c 'import json,sys; d=json.load(open(sys.argv[1])); print((3*d["relmse_2"]+d["relmse_3"])/4)' list.json)
near "$(json_get list.json relmse)" "$want" 1e-12 && pass "explicit channel list" ||
  fail "channels=R,G,B,Z: $(cat list.json), want relmse $want"
# PSNR of identical images is +inf -> JSON null.
run_ok "$REF" "$REF" --psnr --json
grep -q '"psnr": null' out.txt && pass "psnr inf -> null" || fail "psnr: $(cat out.txt)"
# Same result for 1 and 2 threads (deterministic reductions).
run_ok --threads 1 "$NOISY" "$REF" --ssim --relmse --json
cp out.txt t1.json
run_ok --threads 2 "$NOISY" "$REF" --ssim --relmse --json
cmp -s out.txt t1.json && pass "threads 1 == threads 2" || fail "thread results differ"
# AOV images are compared on their colour by default (DESIGN.md's `--denoise ... ref.exr
# --relmse` chain: an RGB result against an AOV reference), equal to naming R,G,B.
S=$TD/dataset
run_ok "$S/sample_noisy.exr" "$S/sample_ref.exr" --relmse --json
cp out.txt aov_default.json
run_ok "$S/sample_noisy.exr" --ch R,G,B "$S/sample_ref.exr" --ch R,G,B --relmse --json
cmp -s out.txt aov_default.json && pass "AOV pair: R,G,B by default" || fail "AOV default: $(cat aov_default.json) vs $(cat out.txt)"
run_ok "$S/sample_noisy.exr" --ch R,G,B "$S/sample_ref.exr" --relmse --json
cmp -s out.txt aov_default.json && pass "RGB vs AOV reference" || fail "RGB vs AOV: $(cat out.txt)"
# Non-finite values: error unless allowed; then excluded and counted.
oiiotool --pattern constant:color=nan,0.5,0.5 4x4 3 --pattern constant:color=0.25,0.5,0.5 16x16 3 \
  --paste +0+0 -o part.exr
oiiotool --pattern constant:color=0.75,0.5,0.5 16x16 3 -o q.exr
expect_fail "16 pixel(s) hold NaN/Inf in 'part.exr'" "" part.exr q.exr --l1
run_ok part.exr q.exr --l1:allow_nonfinite=1 --json
cp out.txt nf.json
near "$(json_get nf.json l1)" 0.16666666666666667 1e-12 && near "$(json_get nf.json l1_nonfinite_pixels)" 16 0 \
  && pass "nonfinite excluded and counted" || fail "nonfinite: $(cat nf.json)"
# session 60: a second metric's count follows its own key (it took the first's); PSNR at an
# extreme range is the finite figure 20 log10(R) - 10 log10(MSE) (R^2 overflowed to inf)
run_ok part.exr q.exr --l1:channels=G --l1:allow_nonfinite=1 --json
cp out.txt nf2.json
json_get nf2.json l1_2_nonfinite_pixels >/dev/null 2>&1 && ! grep -q '"l1_nonfinite_pixels"' nf2.json &&
  pass "the count follows its metric's key" || fail "nonfinite key: $(cat nf2.json)"
oiiotool --pattern constant:color=0.25,0.4,0.5 16x16 3 -o r.exr
run_ok q.exr r.exr --psnr:range=1e155 --json
cp out.txt ps.json
run_ok q.exr r.exr --mse --json
mse=$(json_get out.txt mse)
want=$("$PY" -c "import math,sys; print(20*math.log10(1e155) - 10*math.log10(float(sys.argv[1])))" "$mse")
near "$(json_get ps.json psnr)" "$want" 1e-12 && pass "psnr at range 1e155: $want" ||
  fail "psnr at range 1e155: $(cat ps.json), want $want"
# metrics.md: SSIM needs a finite pixel inside its 5-pixel border, so an 11x11 image with a
# NaN centre fails SSIM alone (exit 1, a runtime error: kpcntool.md), even with allow_nonfinite,
# and fails the command line it is on; L1 on the pair averages the other 120 pixels.
oiiotool --pattern constant:color=nan,0.5,0.5 1x1 3 --pattern constant:color=0.5,0.5,0.5 11x11 3 \
  --paste +5+5 -o nanc.exr
oiiotool --pattern constant:color=0.25,0.5,0.75 11x11 3 -o q11.exr
# expect_rc RC PATTERN ARGS...: kpcntool exits with RC, naming PATTERN on stderr
expect_rc() {
  local want=$1 pat=$2
  shift 2
  "$KT" "$@" >out.txt 2>err.txt
  local rc=$?
  if [ $rc -eq "$want" ] && grep -qF -- "$pat" err.txt; then
    pass "exit $rc naming '$pat': kpcntool $*"
  else
    fail "kpcntool $*: exit $rc (want $want, naming '$pat'), stderr: $(cat err.txt)"
  fi
}
expect_rc 1 "ssim: no finite pixel in the interior" nanc.exr q11.exr --ssim:allow_nonfinite=1 --json
expect_rc 1 "--ssim" nanc.exr q11.exr --l1:allow_nonfinite=1 --ssim:allow_nonfinite=1 --json
# without allow_nonfinite the NaN is the error, reported as every non-finite pixel is: with the
# count and both file names (metrics.md, "Non-finite values"); so is an all-NaN image, where
# no pixel is left for any metric
expect_rc 1 "1 pixel(s) hold NaN/Inf in 'nanc.exr' or 'q11.exr'" nanc.exr q11.exr --ssim
oiiotool --pattern constant:color=nan,0.5,0.5 16x16 3 -o allnan.exr
expect_rc 1 "256 pixel(s) hold NaN/Inf in 'allnan.exr' or 'q.exr'" allnan.exr q.exr --l1
run_ok nanc.exr q11.exr --l1:allow_nonfinite=1 --json
cp out.txt nc.json
# 120 pixels: |0.5 - 0.25| + 0 + |0.5 - 0.75| over 3 channels
near "$(json_get nc.json l1)" 0.16666666666666667 1e-12 && near "$(json_get nc.json l1_nonfinite_pixels)" 1 0 \
  && pass "NaN centre: l1 over the other 120 pixels" || fail "NaN centre l1: $(cat nc.json)"
run_ok q11.exr q11.exr --ssim --json
near "$(json_get out.txt ssim)" 1 0 && pass "11x11 without NaN: ssim 1" || fail "11x11 ssim: $(cat out.txt)"
# one more column: the interior is two pixels, one finite; SSIM is that pixel's, as skimage
# computes it with the NaN pixel set to 0 in both images (metrics.md)
oiiotool --pattern constant:color=nan,0.5,0.5 1x1 3 --pattern checker:width=3:height=2:color1=0.9,0.2,0.6:color2=0.1,0.7,0.3 12x11 3 \
  --paste +5+5 -o nanc12.exr
oiiotool --pattern checker:width=2:height=3:color1=0.8,0.3,0.5:color2=0.2,0.6,0.4 12x11 3 -o q12.exr
run_ok nanc12.exr q12.exr --ssim:allow_nonfinite=1 --json
cp out.txt nc12.json
want=$("$PY" -c '
import sys, numpy as np, OpenImageIO as oiio
from skimage.metrics import structural_similarity
x = oiio.ImageBuf(sys.argv[1]).get_pixels(oiio.FLOAT).astype(np.float64)
y = oiio.ImageBuf(sys.argv[2]).get_pixels(oiio.FLOAT).astype(np.float64)
bad = ~(np.isfinite(x).all(axis=2) & np.isfinite(y).all(axis=2))
assert bad.sum() == 1 and bad[5, 5]
x[bad] = 0; y[bad] = 0
_, S = structural_similarity(x, y, gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
                             data_range=1.0, channel_axis=-1, full=True)
print(repr(float(S[5, 6].mean())))' nanc12.exr q12.exr)
near "$(json_get nc12.json ssim)" "$want" 1e-7 && near "$(json_get nc12.json ssim_nonfinite_pixels)" 1 0 \
  && pass "12x11, NaN at (5,5): ssim of pixel (6,5) = $want" || fail "12x11 NaN: $(cat nc12.json), want $want"
# A figure that leaves double range (eps=1e-320 against a black reference pixel: 1/1e-320)
# prints as null in JSON, like PSNR's +inf: valid JSON (no Infinity/NaN tokens), exit 0.
oiiotool --pattern constant:color=0,0.5,0.25 16x16 3 -o black.exr
oiiotool --pattern constant:color=1,0.5,0.25 16x16 3 -o lit.exr
run_ok lit.exr black.exr --relmse:eps=1e-320 --rell1:eps=1e-320 --l1 --json
cp out.txt eps.json
"$PY" -c '
import json, sys
def bad(tok): raise ValueError("non-JSON token " + tok)
d = json.load(open(sys.argv[1]), parse_constant=bad)
assert set(d) == {"relmse", "rell1", "l1"}, d
assert d["relmse"] is None and d["rell1"] is None, d
assert abs(d["l1"] - 1 / 3) < 1e-12, d' eps.json && grep -q '"relmse": null' eps.json &&
  pass "eps=1e-320: relmse and rell1 null in valid JSON" || fail "eps=1e-320: $(cat eps.json)"
# the same figures stay finite where no reference pixel is black
run_ok black.exr lit.exr --relmse:eps=1e-320 --json
near "$(json_get out.txt relmse)" 0.33333333333333333 1e-12 && pass "eps=1e-320 finite elsewhere" ||
  fail "eps=1e-320 against lit: $(cat out.txt)"
finish
