#!/bin/sh
# tools/error_budget.py: zero for a perfect input, its kpcn figure equals kpcntool's relMSE,
# the branch split adds up, exact identities and independent recomputation
# (error_budget_check.py), bad input is a clear error.
# usage: test_error_budget.sh SCRIPT KPCNTOOL FIXTURE
set -u
S=$1; T=$2; F=$3
D=$(mktemp -d /tmp/kpcn_budget_XXXXXX)
trap 'rm -rf "$D"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
"$F" "$D" >/dev/null || fail "fixture"
check() { # JSON EXPR: EXPR (Python, d = the JSON object) must be true
  /usr/bin/python3 -c "import json,sys; d=json.loads(sys.argv[1]); sys.exit(0 if ($2) else 1)" "$1" ||
    fail "$2 does not hold for $1"
}
# the render against itself: every oracle figure is zero (colour = diffuse + specular to float rounding)
j=$(/usr/bin/python3 "$S" "$D/aov.exr" "$D/aov.exr") || fail "self comparison"
check "$j" "d['noisy'] == 0 and max(d['irradiance_oracle'], d['diffuse_exact'], d['specular_exact']) < 1e-12"
# with a model: kpcn equals kpcntool's own relMSE of the denoised image
j=$(/usr/bin/python3 "$S" "$D/aov.exr" "$D/aov.exr" --model "$D/model.safetensors" --kpcntool "$T") || fail "with model"
"$T" "$D/aov.exr" --denoise:model="$D/model.safetensors" -o "$D/den.exr" || fail "denoise"
r=$("$T" --json "$D/den.exr" "$D/aov.exr" --ch R,G,B --relmse) || fail "relmse"
check "$j" "abs(d['kpcn'] - json.loads('$r')['relmse']) <= 1e-6 * d['kpcn'] and d['kpcn'] > 0"
# the two branch parts are the two halves of one residual (kpcn's error = |e_d + e_s|^2 in a
# weighted norm), so the triangle inequality bounds the whole by them from both sides
check "$j" "0 < d['kpcn_diffuse'] and 0 < d['kpcn_specular']"
# the worst-1 % share, recomputed here from the two image files
t=$(/usr/bin/python3 - "$D/den.exr" "$D/aov.exr" <<'PY'
import sys
import numpy as np
import OpenImageIO as oiio
def rgb(p):
    b = oiio.ImageBuf(p)
    n = list(b.spec().channelnames)
    px = b.get_pixels(oiio.FLOAT)
    return np.stack([px[..., n.index(c)] for c in "RGB"], -1).astype(np.float64)
x, y = rgb(sys.argv[1]), rgb(sys.argv[2])
e = np.sort(((x - y) ** 2 / (y ** 2 + 0.01)).mean(-1).ravel())
k = max(1, e.size // 100)
print(repr(e[-k:].sum() / e.sum()))
PY
) || fail "worst 1 % share"
check "$j" "0.01 < d['kpcn_top1pct'] < 1 and abs(d['kpcn_top1pct'] - $t) <= 1e-9"
check "$j" "abs(d['kpcn_diffuse'] ** 0.5 - d['kpcn_specular'] ** 0.5) <= d['kpcn'] ** 0.5 * 1.000001"
check "$j" "d['kpcn'] ** 0.5 <= (d['kpcn_diffuse'] ** 0.5 + d['kpcn_specular'] ** 0.5) * 1.000001"
# independent checks: exact identities on one-buffer perturbations, the network-free figures
# recomputed from their definitions, the branch split computed the other way round (also for
# a model that records an exposure); see the helper's docstring
/usr/bin/python3 "$(dirname "$0")/error_budget_check.py" "$S" "$T" "$D" || fail "error_budget_check.py"
# bad input: a reference without diffuse.*, a missing file, a bad model
if /usr/bin/python3 "$S" "$D/aov.exr" "$D/aov_nodiffuse.exr" 2>"$D/err"; then fail "missing diffuse accepted"; fi
grep -q "diffuse.R" "$D/err" || fail "error does not name diffuse.R: $(cat "$D/err")"
if /usr/bin/python3 "$S" "$D/none.exr" "$D/aov.exr" 2>"$D/err"; then fail "missing file accepted"; fi
grep -q "none.exr" "$D/err" || fail "error does not name the file: $(cat "$D/err")"
if /usr/bin/python3 "$S" "$D/aov.exr" "$D/aov.exr" --model "$D/none.safetensors" --kpcntool "$T" 2>"$D/err"; then
  fail "missing model accepted"
fi
grep -q "none.safetensors" "$D/err" || fail "error does not name the model: $(cat "$D/err")"
echo "test_error_budget: all passed"
