#!/bin/sh
# kpcn-dataset end to end with a fake renderer (fast) plus one tiny real render when
# kpcn-render exists: split by base scene, shards partition the jobs, resume after a
# killed run renders nothing twice, degenerate variants are rejected, patches build a
# store and refuse incomplete datasets, bad arguments fail cleanly.
# usage: test_dataset_tool.sh KPCN_DATASET TESTDATA_DATASET_DIR TMPDIR [KPCN_RENDER]
set -u
DS=$1; TD=$2; T=$3; REAL=${4:-}
FAKE=$TD/fake_render.sh
fails=0; checks=0
ok() { checks=$((checks+1)); if ! eval "$1"; then fails=$((fails+1)); echo "FAIL: $2" >&2; fi; }
rm -rf "$T"; mkdir -p "$T"

# ---- plan: split by base scene (fractions), variants only for train ----
"$DS" plan --scenes "$TD/scenes" --variants 2 --seed 3 --spp 2,4 --ref-spp 128 \
  --split train:0.34,val:0.33,test:0.33 -o "$T/d" > "$T/plan.out"
rc=$?
ok '[ $rc -eq 0 ] && [ -f "$T/d/manifest.jsonl" ]' "plan succeeds"
# every base scene in exactly one split
nsplit=$(sed 's/.*"scene":"\([^"]*\)".*"split":"\([^"]*\)".*/\1 \2/' "$T/d/manifest.jsonl" | sort -u | awk '{print $1}' | uniq -d | wc -l)
ok '[ "$nsplit" -eq 0 ]' "a base scene appears in two splits"
nscenes_split=$(sed 's/.*"split":"\([^"]*\)".*/\1/' "$T/d/manifest.jsonl" | sort -u | wc -l)
ok '[ "$nscenes_split" -eq 3 ]' "three splits used (got $nscenes_split)"
# variants > 0 only in train
ok '! grep -v "\"split\":\"train\"" "$T/d/manifest.jsonl" | grep -q "\"variant\":[1-9]"' "eval splits must not be perturbed"
ntrain=$(grep -c '"split":"train"' "$T/d/manifest.jsonl")
ok '[ "$ntrain" -eq 11 ]' "train scene: 3 variants x 3 jobs + 2 previews = 11 (got $ntrain)"
# deterministic: planning again gives the same manifest
cp "$T/d/manifest.jsonl" "$T/m1"
"$DS" plan --scenes "$TD/scenes" --variants 2 --seed 3 --spp 2,4 --ref-spp 128 \
  --split train:0.34,val:0.33,test:0.33 -o "$T/d" > /dev/null
ok 'cmp -s "$T/m1" "$T/d/manifest.jsonl"' "plan is deterministic"
# a different plan into the same directory is refused
"$DS" plan --scenes "$TD/scenes" --variants 5 -o "$T/d" 2> "$T/err" > /dev/null
rc=$?
ok '[ $rc -eq 1 ] && grep -q "different plan" "$T/err"' "different plan refused"
# explicit names, bad specs
"$DS" plan --scenes "$TD/scenes" --variants 1 --split train:cornell-box+cornell-teal,test:cornell-wide -o "$T/n" > /dev/null
rc=$?
ok '[ $rc -eq 0 ] && grep -q "\"scene\":\"cornell-wide\".*\"split\":\"test\"" "$T/n/manifest.jsonl"' "named split"
"$DS" plan --scenes "$TD/scenes" --split train:cornell-box -o "$T/bad1" 2> "$T/err"
rc=$?
ok '[ $rc -eq 2 ] && grep -q "in no split" "$T/err"' "unassigned scene is an error"
"$DS" plan --scenes "$TD/scenes" --split train:nosuch,test:cornell-box+cornell-teal+cornell-wide -o "$T/bad2" 2> "$T/err"
rc=$?
ok '[ $rc -eq 2 ] && grep -q "nosuch" "$T/err"' "unknown scene in split"
"$DS" plan --scenes "$TD/nonexistent" -o "$T/bad3" 2> /dev/null
rc=$?
ok '[ $rc -eq 1 ]' "missing scenes dir"
"$DS" plan --scenes "$TD/scenes" --spp 4,x -o "$T/bad4" 2> /dev/null
rc=$?
ok '[ $rc -eq 2 ] && [ ! -e "$T/bad4" ]' "bad --spp, nothing written"

# ---- shards partition the job list ----
"$DS" run "$T/d" --list > "$T/all"
: > "$T/union"
for i in 0 1 2; do "$DS" run "$T/d" --list --shard $i/3 >> "$T/union"; done
ok '[ $(wc -l < "$T/all") -eq 15 ]' "15 render jobs"
ok '[ "$(sort "$T/all")" = "$(sort "$T/union")" ]' "shards cover every job"
ok '[ -z "$(sort "$T/union" | uniq -d)" ]' "shards are disjoint"
"$DS" run "$T/d" --shard 3/3 2> /dev/null
rc=$?
ok '[ $rc -eq 2 ]' "bad shard rejected"

# ---- resume after a killed run ----
export FAKE_LOG="$T/log1" FAKE_SLEEP=0.3
"$DS" run "$T/d" --jobs 2 --renderer "$FAKE" > /dev/null 2>&1 &
pid=$!
sleep 1.2
kill -TERM $pid
wait $pid
rc=$?
ok '[ $rc -eq 130 ]' "interrupted run exits 130 (got $rc)"
ls "$T"/d/renders/*/*.exr 2>/dev/null | grep -v part | sed "s|$T/d/||" | sort > "$T/done1"
n1=$(wc -l < "$T/done1")
ok '[ "$n1" -gt 0 ] && [ "$n1" -lt 18 ]' "some but not all outputs after the kill ($n1)"
ok '[ -z "$(ls "$T"/d/renders/*/*.part* 2>/dev/null)" ]' "no part files left after SIGTERM"
# a wrapper renderer's children are stopped with it (the run signals the renderer's process
# group): otherwise they keep running and write part files after the run has removed them
"$DS" plan --scenes "$TD/scenes" --variants 1 --seed 3 --spp 2 --ref-spp 128 \
  --split train:0.34,val:0.33,test:0.33 -o "$T/w" > /dev/null
export FAKE_LOG="$T/logw" FAKE_SLEEP=0.8 FAKE_DETACH=1
"$DS" run "$T/w" --jobs 2 --renderer "$FAKE" > /dev/null 2>&1 &
pid=$!
sleep 0.3
kill -TERM $pid
wait $pid
sleep 1.2
ok '[ -z "$(ls "$T"/w/renders/*/*.part* 2>/dev/null)" ] && ! grep -q "^done" "$T/logw"' \
  "a wrapper renderer's children stop with it"
unset FAKE_DETACH
export FAKE_LOG="$T/log2" FAKE_SLEEP=0
"$DS" run "$T/d" --jobs 2 --renderer "$FAKE" > "$T/run2.out" 2>&1
rc=$?
ok '[ $rc -eq 0 ]' "resumed run succeeds"
sed -n 's|^start .*/d/||p' "$T/log2" | sort > "$T/started2"
ok '[ -z "$(comm -12 "$T/done1" "$T/started2")" ]' "resume re-rendered a finished output"
ok '[ $(ls "$T"/d/renders/*/*.exr | grep -v preview | wc -l) -eq 15 ]' "all 15 outputs exist"
ok '[ -z "$(sort "$T/started2" | uniq -d)" ]' "a job started twice in one run"
export FAKE_LOG="$T/log3"
"$DS" run "$T/d" --jobs 2 --renderer "$FAKE" > "$T/run3.out" 2>&1
ok '[ ! -s "$T/log3" ] && grep -q "rendered 0, already done 15" "$T/run3.out"' "third run renders nothing"

# ---- degenerate variant rejection + patches ----
"$DS" plan --scenes "$TD/scenes" --variants 2 --seed 3 --spp 2,4 --ref-spp 128 \
  --split train:cornell-box+cornell-teal,test:cornell-wide -o "$T/r" > /dev/null
export FAKE_LOG="$T/logr" FAKE_BLACK="cornell-teal/v001"
"$DS" run "$T/r" --jobs 2 --renderer "$FAKE" > "$T/runr.out" 2>&1
rc=$?
ok '[ $rc -eq 0 ] && grep -q "rejected cornell-teal/v001: mostly black" "$T/runr.out"' "black variant rejected"
ok '! grep -q "start .*cornell-teal/v001_[0-9r]" "$T/logr"' "rejected variant not rendered"
ok 'grep -q "start .*cornell-teal/v002_ref" "$T/logr"' "other variants rendered"
unset FAKE_BLACK
"$DS" patches "$T/r" --size 8 --per-image 5 -o "$T/r/train.kps" > "$T/p.out"
rc=$?
ok '[ $rc -eq 0 ] && [ -s "$T/r/train.kps" ] && grep -q "10 image pairs (2 rejected" "$T/p.out"' "patch store built ($(cat "$T/p.out"))"
rm "$T/r/renders/cornell-box/v001_ref128spp.exr"
"$DS" patches "$T/r" --size 8 --per-image 5 -o "$T/r/train2.kps" 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && [ ! -e "$T/r/train2.kps" ] && grep -q "not rendered yet" "$T/err"' "incomplete dataset refused"
"$DS" patches "$T/r" --size 8 --per-image 5 --allow-partial -o "$T/r/train2.kps" > /dev/null
rc=$?
ok '[ $rc -eq 0 ] && [ -s "$T/r/train2.kps" ]' "--allow-partial"
# two dataset directories into one store: the pairs of both, the sources named with their directory
np_r=$("$DS" patches "$T/r" --size 8 --per-image 5 --allow-partial -o "$T/r/one.kps" | sed 's/.*: \([0-9]*\) image pairs.*/\1/')
np_d=$("$DS" patches "$T/d" --size 8 --per-image 5 -o "$T/d/one.kps" | sed 's/.*: \([0-9]*\) image pairs.*/\1/')
np_rd=$("$DS" patches "$T/r" "$T/d" --size 8 --per-image 5 --allow-partial -o "$T/both.kps" | sed 's/.*: \([0-9]*\) image pairs.*/\1/')
echo "two directories: $np_rd pairs = $np_r + $np_d"
ok '[ -n "$np_r" ] && [ -n "$np_d" ] && [ "$np_rd" -eq $((np_r + np_d)) ]' "two directories: $np_rd pairs = $np_r + $np_d"
ok 'grep -a -q "$T/d/renders/" "$T/both.kps" && grep -a -q "$T/r/renders/" "$T/both.kps"' "sources carry their directory"
"$DS" patches "$T/r" "$T/nothing" --size 8 --allow-partial -o "$T/none.kps" 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && [ ! -e "$T/none.kps" ] && grep -q "nothing" "$T/err"' "a second directory without manifest"
"$DS" patches "$T/r" --size 64 --allow-partial -o "$T/r/big.kps" 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && [ ! -e "$T/r/big.kps" ] && grep -q "does not fit" "$T/err"' "patch larger than image"
"$DS" run "$T/nothing" 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && grep -q "manifest.jsonl" "$T/err"' "run without manifest"

# ---- one tiny real render ----
if [ -n "$REAL" ] && [ -x "$REAL" ]; then
  "$DS" plan --scenes "$TD/scenes" --variants 1 --seed 1 --spp 2 --ref-spp 8 --resolution 24x24 \
    --split train:cornell-box,val:cornell-teal,test:cornell-wide -o "$T/real" > /dev/null
  "$DS" run "$T/real" --jobs 2 --renderer "$REAL" > "$T/real.out" 2>&1
  ok '[ $? -eq 0 ]' "real render run ($(cat "$T/real.out"))"
  "$DS" patches "$T/real" --size 8 --per-image 4 -o "$T/real/train.kps" > /dev/null
  ok '[ $? -eq 0 ] && [ -s "$T/real/train.kps" ]' "real patches"
else
  echo "kpcn-render not built: real render part skipped"
fi
echo "dataset_tool: $checks checks, $((checks-fails)) passed, $fails failed"
[ $fails -eq 0 ]
