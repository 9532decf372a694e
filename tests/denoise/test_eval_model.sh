#!/bin/sh
# tools/eval_model.py: pairs found by kpcn-dataset's layout and filtered by variant and spp;
# its figures recomputed from kpcntool's own per-pair relMSE and PSNR (geometric and
# arithmetic means, mean PSNR, to 1e-9); bad input is a clear error.
# usage: test_eval_model.sh SCRIPT KPCNTOOL FIXTURE
set -u
S=$1; T=$2; F=$3
D=$(mktemp -d /tmp/kpcn_evalm_XXXXXX)
trap 'rm -rf "$D"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
"$F" "$D" >/dev/null || fail "fixture"
M="$D/model.safetensors"
# two scenes; the fixture's noisy AOV render as 4 and 16 spp of v000 and v001, its reference
# (a denoised copy, so every relMSE differs and none is 0) as each variant's reference
"$T" "$D/aov.exr" --denoise:method=bilateral -o "$D/ref.exr" || fail "reference"
"$T" "$D/aov.exr" --denoise:method=nlmeans -o "$D/ref2.exr" || fail "reference 2"
for s in a b; do
  mkdir -p "$D/ds/renders/$s"
  for v in 000 001; do
    cp "$D/aov.exr" "$D/ds/renders/$s/v${v}_4spp.exr"
    cp "$D/aov.exr" "$D/ds/renders/$s/v${v}_16spp.exr"
  done
  cp "$D/ref.exr" "$D/ds/renders/$s/v000_ref1024spp.exr"
  cp "$D/ref2.exr" "$D/ds/renders/$s/v001_ref1024spp.exr"
done
j=$(/usr/bin/python3 "$S" "$M" "$D/ds" --kpcntool "$T" --pairs "$D/pairs.tsv") || fail "run"
"$T" "$D/aov.exr" --denoise:model="$M" -o "$D/den.exr" || fail "denoise"
r1=$("$T" "$D/den.exr" "$D/ref.exr" --ch R,G,B --relmse --psnr:display=srgb --json) || fail "m1"
r2=$("$T" "$D/den.exr" "$D/ref2.exr" --ch R,G,B --relmse --psnr:display=srgb --json) || fail "m2"
/usr/bin/python3 - "$j" "$r1" "$r2" "$D/pairs.tsv" <<'PY' || fail "figures: $j"
import json, math, sys
d, a, b = (json.loads(x) for x in sys.argv[1:4])
rel = [a["relmse"], b["relmse"]] * 4  # 2 scenes x 2 spp x (v000, v001)
psnr = [a["psnr"], b["psnr"]] * 4
close = lambda x, y: abs(x - y) <= 1e-9 * abs(y)
assert d["pairs"] == 8, d
assert close(d["geomean"], math.exp(sum(map(math.log, rel)) / 8)), d
assert close(d["mean"], sum(rel) / 8), d
assert close(d["psnr"], sum(psnr) / 8), d
rows = [l.split("\t") for l in open(sys.argv[4])]
assert len(rows) == 8 and {r[2] for r in rows} == {"v000", "v001"}, rows
PY
# filters: v001 at 16 spp only -> the second reference's figure, twice
j=$(/usr/bin/python3 "$S" "$M" "$D/ds" --kpcntool "$T" --variants 1 --spp 16) || fail "filtered"
/usr/bin/python3 -c "import json,sys; d=json.loads(sys.argv[1]); r=json.loads(sys.argv[2])['relmse']
assert d['pairs'] == 2 and abs(d['geomean'] - r) <= 1e-9 * r, d" "$j" "$r2" || fail "filtered: $j"
# bad input: no pairs, no renders/ folder, a pair without its reference, a junk list
bad() {
  pat=$1; shift
  if /usr/bin/python3 "$S" "$@" --kpcntool "$T" >"$D/out" 2>"$D/err"; then fail "accepted: $*"; fi
  grep -qF -- "$pat" "$D/err" || fail "message lacks '$pat': $(cat "$D/err")"
  [ ! -s "$D/out" ] || fail "printed a result for: $*"
}
bad "no pairs found" "$M" "$D/ds" --spp 64
bad "has no renders/ folder" "$M" "$D"
bad "is not a comma-separated list" "$M" "$D/ds" --variants 1,x
# an output that cannot be written is refused before any pair is measured (it failed at the end)
bad "--pairs '$D/nodir/p.tsv': cannot write a file there" "$M" "$D/ds" --pairs "$D/nodir/p.tsv"
# without --kpcntool, the binaries come from $KPCN_BIN as in the shell tools (it was ignored)
if KPCN_BIN="$D/nobin" /usr/bin/python3 "$S" "$M" "$D/ds" >"$D/out" 2>"$D/err"; then
  fail "KPCN_BIN ignored"
fi
grep -qF "no kpcntool at '$D/nobin/kpcntool/kpcntool'" "$D/err" || fail "KPCN_BIN: $(cat "$D/err")"
# two references for a variant (training_data.sh's v1 has 1024- and 4096-spp ones): the one of
# most samples by default, --ref-spp picks one (it was refused); a missing count is named
cp "$D/ref2.exr" "$D/ds/renders/a/v000_ref4096spp.exr"
j=$(/usr/bin/python3 "$S" "$M" "$D/ds" --kpcntool "$T" --variants 0 --spp 16) || fail "two refs"
/usr/bin/python3 -c "import json,sys; d=json.loads(sys.argv[1]); a=json.loads(sys.argv[2])['relmse']
b=json.loads(sys.argv[3])['relmse']
assert d['pairs'] == 2 and abs(d['mean'] - (a + b) / 2) <= 1e-9 * b, d" "$j" "$r1" "$r2" ||
  fail "most samples not chosen: $j"
j=$(/usr/bin/python3 "$S" "$M" "$D/ds" --kpcntool "$T" --variants 0 --spp 16 --ref-spp 1024) ||
  fail "--ref-spp 1024"
/usr/bin/python3 -c "import json,sys; d=json.loads(sys.argv[1]); a=json.loads(sys.argv[2])['relmse']
assert d['pairs'] == 2 and abs(d['mean'] - a) <= 1e-9 * a, d" "$j" "$r1" || fail "--ref-spp: $j"
bad "has no 4096-spp reference (v000_ref4096spp.exr; it has 1024 spp)" "$M" "$D/ds" --variants 0 \
  --ref-spp 4096
bad "is not one positive sample count" "$M" "$D/ds" --ref-spp 0
rm "$D/ds/renders/a/v000_ref4096spp.exr"
rm "$D/ds/renders/b/v001_ref1024spp.exr"
bad "v001_16spp.exr has no reference" "$M" "$D/ds"
bad "no model file" "$D/nope.safetensors" "$D/ds"
echo "test_eval_model: ok"
