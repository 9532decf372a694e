#!/bin/sh
# tools/variance_split.py against synthetic results with a known bias and noise level:
# results = ref + b + N(0, s^2) per pixel, so the variance part must come out as s^2 / (ref^2
# + 0.01) averaged, and the rest as b^2 / (ref^2 + 0.01); bad input is a clear error.
# usage: test_variance_split.sh SCRIPT
set -u
S=$1
D=$(mktemp -d /tmp/kpcn_varsplit_XXXXXX)
trap 'rm -rf "$D"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
/usr/bin/python3 - "$D" <<'PY' || fail "fixture"
import sys, numpy as np, OpenImageIO as oiio
d = sys.argv[1]
rng = np.random.default_rng(7)
h, w = 96, 128
y, x = np.mgrid[0:h, 0:w]
ref = np.stack([0.2 + 0.5 * x / w, 0.3 + 0.4 * y / h, np.full((h, w), 0.5)], -1)
def save(path, img, names=("R", "G", "B")):
    spec = oiio.ImageSpec(w, h, len(names), oiio.FLOAT)
    spec.channelnames = names
    out = oiio.ImageOutput.create(path)
    out.open(path, spec)
    out.write_image(img.astype(np.float32))
    out.close()
save(d + "/ref.exr", ref)
for i in range(16):
    save(d + "/o%d.exr" % i, ref + 0.02 + rng.normal(0, 0.05, ref.shape))
spec = oiio.ImageSpec(64, 48, 3, oiio.FLOAT)
out = oiio.ImageOutput.create(d + "/small.exr"); out.open(d + "/small.exr", spec)
out.write_image(np.zeros((48, 64, 3), np.float32)); out.close()
save(d + "/xyz.exr", ref, ("X", "Y", "Z"))
wt = 1 / (ref ** 2 + 0.01)
open(d + "/expect", "w").write("%r %r" % (float(np.mean(0.05 ** 2 * wt)), float(np.mean(0.02 ** 2 * wt))))
PY
j=$(/usr/bin/python3 "$S" "$D/ref.exr" "$D"/o*.exr) || fail "run"
read -r ev er < "$D/expect"
# 16 results x 36864 values: the sample variance's mean is within ~0.5 % of its expectation
/usr/bin/python3 -c "
import json, sys
d = json.loads(sys.argv[1]); ev, er = float(sys.argv[2]), float(sys.argv[3])
ok = abs(d['variance'] / ev - 1) < 0.02 and abs(d['rest'] - er) < 0.02 * ev and d['n'] == 16
ok = ok and abs(d['variance_share'] - d['variance'] / d['relmse']) < 1e-12 and 0.05 <= d['top_share'] < 0.2
sys.exit(0 if ok else 1)" "$j" "$ev" "$er" || fail "figures off: $j (expected variance $ev, rest $er)"
# bad input: one result, a size mismatch, no R channel
if /usr/bin/python3 "$S" "$D/ref.exr" "$D/o0.exr" 2>"$D/err"; then fail "one result accepted"; fi
grep -q "at least two" "$D/err" || fail "message: $(cat "$D/err")"
if /usr/bin/python3 "$S" "$D/ref.exr" "$D/o0.exr" "$D/small.exr" 2>"$D/err"; then fail "size mismatch accepted"; fi
grep -q "64x48" "$D/err" || fail "message: $(cat "$D/err")"
if /usr/bin/python3 "$S" "$D/ref.exr" "$D/o0.exr" "$D/xyz.exr" 2>"$D/err"; then fail "no R accepted"; fi
grep -q "no channel R" "$D/err" || fail "message: $(cat "$D/err")"
echo "variance_split: synthetic variance and bias recovered, bad input refused"
