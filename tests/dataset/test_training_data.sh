#!/bin/sh
# tools/training_data.sh --plan-only: every dataset of docs/dataset.md's recipes plans as the
# sessions that rendered it recorded (jobs and camera samples, from docs/dataset.md), the plans
# are the ones recorded here (a fingerprint of each manifest and its perturbed scene files, the
# testdata and output paths masked: a change to plan, the perturbations or rooms.py that alters
# the data fails here and must be documented), a second call resumes instead of planning again,
# nothing is rendered, and bad arguments are refused.
# usage: test_training_data.sh SCRIPT KPCN_BIN
set -u
S=$1; B=$2
D=$(mktemp -d /tmp/kpcn_tdata_XXXXXX)
trap 'rm -rf "$D"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
KPCN_BIN=$B bash "$S" --plan-only "$D/out" >"$D/plan.txt" 2>"$D/err" || fail "plan-only: $(cat "$D/err")"
# docs/dataset.md: "284 jobs ..., 1.67e9 camera samples planned" (v1), "588 jobs ... 3.4e9" (v2), ...
cat >"$D/want.txt" <<'EOF'
v1: 284 jobs, 1.67e+09 camera samples
v2: 588 jobs, 3.4e+09 camera samples
v2val: 126 jobs, 7.66e+08 camera samples
v3: 352 jobs, 2.04e+09 camera samples
v3val: 112 jobs, 6.81e+08 camera samples
rooms: 288 jobs, 1.82e+09 camera samples
roomsval: 48 jobs, 3.4e+08 camera samples
rooms2: 432 jobs, 2.72e+09 camera samples
roomsval2: 48 jobs, 3.4e+08 camera samples
rooms3: 192 jobs, 1.36e+09 camera samples
rooms4: 144 jobs, 1.02e+09 camera samples
v4a: 81 jobs, 5.11e+08 camera samples
v4b: 112 jobs, 6.81e+08 camera samples
roomsval3: 48 jobs, 3.4e+08 camera samples
rooms5: 192 jobs, 1.36e+09 camera samples
v4c: 112 jobs, 6.81e+08 camera samples
v4d: 81 jobs, 5.11e+08 camera samples
rooms6: 384 jobs, 2.72e+09 camera samples
rooms7: 384 jobs, 2.72e+09 camera samples
rooms8: 384 jobs, 2.72e+09 camera samples
rooms9: 384 jobs, 2.72e+09 camera samples
EOF
diff "$D/want.txt" "$D/plan.txt" >"$D/diff" || fail "plans differ from docs/dataset.md's figures: $(cat "$D/diff")"
[ -z "$(find "$D/out" -name '*.exr' | head -1)" ] || fail "--plan-only rendered something"
# the second call finds the plans and lists the same figures from their manifests
KPCN_BIN=$B bash "$S" --plan-only "$D/out" >"$D/again.txt" 2>"$D/err" || fail "second call: $(cat "$D/err")"
cmp -s "$D/plan.txt" "$D/again.txt" || fail "the resumed call lists other figures: $(diff "$D/plan.txt" "$D/again.txt")"
# fingerprints of the plans as this code makes them (session 40; v1's manifest and scene files
# are also byte for byte those of the plan session 39 rendered and measured docs/results.md on)
/usr/bin/python3 - "$D/out" "$(cd "$(dirname "$S")/.." && pwd)/testdata/scenes" >"$D/fp.txt" <<'PY' || fail "fingerprints"
import hashlib, os, sys
out, scenes = sys.argv[1], sys.argv[2]
for l in open(os.path.join(os.path.dirname(out), 'plan.txt')):
    d = l.split(':')[0]
    root = os.path.join(out, 'dataset', d)
    files = ['manifest.jsonl'] + sorted(os.path.relpath(os.path.join(dp, f), root)
                                        for dp, _, fs in os.walk(os.path.join(root, 'scenes')) for f in fs)
    h = hashlib.sha256()
    for f in files:
        t = open(os.path.join(root, f), 'rb').read()
        t = t.replace(scenes.encode(), b'@SCENES@').replace(out.encode(), b'@OUT@')
        h.update(f.encode() + b'\0' + t + b'\0')
    print(d, h.hexdigest()[:16])
PY
cat >"$D/fpwant.txt" <<'EOF'
v1 412827a2986139d3
v2 cac94ade68e8e2cb
v2val 14109c8197957382
v3 a0e74c2960bc71af
v3val daa02ac80c0ceccb
rooms fe38180532fcf451
roomsval 142c840c616f55eb
rooms2 262794f3e0f40218
roomsval2 9f3d4ccf8880fd14
rooms3 4e5cf6029c4dc242
rooms4 c4394326b7cc2770
v4a 0d3764da6ad09cd6
v4b 551d658c490b770d
roomsval3 0adb6f46782087e9
rooms5 e0784fd700ad0843
v4c afe60d53b620c70a
v4d 910d4d2304ecb1e2
rooms6 92ccf7bcb21741ff
rooms7 f2e76fb4015bc02b
rooms8 137bf5ba34ae7c1d
rooms9 6dee73f228e3de7b
EOF
diff "$D/fpwant.txt" "$D/fp.txt" >"$D/diff" || fail "plans changed (fingerprints): $(cat "$D/diff")"
# a dataset planned otherwise (another seed here) is refused, not rendered into
sed -i 's/"seed":"[0-9]*"/"seed":"1"/' "$D/out/dataset/roomsval/manifest.jsonl"
if KPCN_BIN=$B bash "$S" --plan-only "$D/out" roomsval >/dev/null 2>"$D/err"; then fail "a changed plan accepted"; fi
grep -q "dataset/roomsval was planned otherwise" "$D/err" || fail "changed plan message: $(cat "$D/err")"
[ -z "$(find "$D/out" -name '.plan.*' | head -1)" ] || fail "a scratch plan was left behind"
# a subset, and bad arguments: an unknown dataset or option is refused before anything is planned
KPCN_BIN=$B bash "$S" --plan-only "$D/sub" roomsval v1 >"$D/sub.txt" 2>"$D/err" || fail "subset: $(cat "$D/err")"
[ "$(cut -d: -f1 "$D/sub.txt" | paste -sd' ')" = "roomsval v1" ] || fail "subset lists $(cat "$D/sub.txt")"
[ ! -e "$D/sub/dataset/v2" ] || fail "subset planned v2"
if KPCN_BIN=$B bash "$S" --plan-only "$D/bad" nosuch 2>"$D/err"; then fail "unknown dataset accepted"; fi
grep -q "unknown dataset 'nosuch'" "$D/err" || fail "unknown dataset message: $(cat "$D/err")"
[ ! -e "$D/bad/dataset" ] || fail "an unknown dataset left a dataset folder"
if KPCN_BIN=$B bash "$S" --frobnicate "$D/bad2" 2>"$D/err"; then fail "unknown option accepted"; fi
grep -q "unknown option '--frobnicate'" "$D/err" || fail "unknown option message: $(cat "$D/err")"
if KPCN_BIN=$D/none bash "$S" --plan-only "$D/bad3" 2>"$D/err"; then fail "missing kpcn-dataset accepted"; fi
grep -q "no kpcn-dataset" "$D/err" || fail "missing binary message: $(cat "$D/err")"
echo "test_training_data: all passed"
