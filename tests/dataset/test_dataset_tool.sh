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
for split in "train:0.5,,val:0.5" "train:0.5,val:0.5," ",train:1"; do
  "$DS" plan --scenes "$TD/scenes" --split "$split" -o "$T/bad6" 2> "$T/err"
  rc=$?
  ok '[ $rc -eq 2 ] && [ ! -e "$T/bad6" ] && grep -q "has an empty item" "$T/err"' "plan --split $split refused (rc $rc)"
done
# a split asked for with a share that rounds to no scene of the three is named, not left empty
for split in "train:0.8,val:0.1" "train:0.01,val:0.5,test:0.49"; do
  "$DS" plan --scenes "$TD/scenes" --split "$split" -o "$T/bad7" 2> "$T/err"
  rc=$?
  ok '[ $rc -eq 2 ] && [ ! -e "$T/bad7" ] && grep -q "split .* of 3 base scenes) gets no scene" "$T/err"' \
    "plan --split $split: an empty split refused (rc $rc: $(cat "$T/err"))"
done
# sizes past int range wrapped to 16x8 through sscanf; blanks and signs are no number either
for res in 4294967312x4294967304 " 16x16" +16x16 16x16x 16 -16x16; do
  "$DS" plan --scenes "$TD/scenes" --resolution "$res" -o "$T/bad8" 2> "$T/err"
  rc=$?
  ok '[ $rc -eq 2 ] && [ ! -e "$T/bad8" ] && grep -q "for --resolution" "$T/err"' \
    "plan --resolution '$res' refused (rc $rc)"
done
# a count twice would plan one job (one output file) twice; an empty item is a typo
for spp in 2,2 4,2,4 1,,2 2, ,2; do
  "$DS" plan --scenes "$TD/scenes" --spp "$spp" -o "$T/bad5" 2> "$T/err"
  rc=$?
  ok '[ $rc -eq 2 ] && [ ! -e "$T/bad5" ] && grep -q "distinct integers" "$T/err"' "plan --spp $spp refused (rc $rc)"
done
# bad values: exit 2, the option and value named, nothing written
bad_plan() { # PATTERN DESC PLAN-ARGS...
  pat=$1; desc=$2; shift 2
  rm -rf "$T/bp"
  "$DS" plan --scenes "$TD/scenes" --variants 1 -o "$T/bp" "$@" > /dev/null 2> "$T/err"
  rc=$?
  ok '[ $rc -eq 2 ] && [ ! -e "$T/bp" ] && grep -F -q -- "$pat" "$T/err"' "$desc (rc $rc: $(cat "$T/err"))"
}
bad_plan "'inf' for --camera" "--camera inf refused" --camera inf
bad_plan "'inf' for --material" "--material inf refused" --material inf
bad_plan "'inf' for --light" "--light inf refused" --light inf
bad_plan "'nan' for --env" "--env nan refused" --env nan
bad_plan "'-1' for --seed" "negative --seed refused" --seed -1
bad_plan "'18446744073709551616' for --seed" "--seed past 2^64 refused" --seed 18446744073709551616
bad_plan "'1.5' for --bsdf-swap (a probability in [0, 1])" "--bsdf-swap above 1 refused" --bsdf-swap 1.5
bad_plan "'-0.5' for --texture-bitmap (a probability in [0, 1])" "--texture-bitmap below 0 refused" --texture-bitmap -0.5
bad_plan "'7e3' for --variants" "--variants must be an integer" --variants 7e3
bad_plan "'17' for --albedo-footprint (an integer in [1, 16])" "--albedo-footprint 17 refused" \
  --albedo-footprint 17
bad_plan "sum to 2.5" "split fractions summing past 1 refused" --split train:0.5,val:1,test:1
bad_plan "'train' is named twice" "duplicate split (fractions)" --split train:0.5,train:0.5
bad_plan "'train' is named twice" "duplicate split (names)" \
  --split train:cornell-box,train:cornell-teal+cornell-wide
"$DS" plan --scenes "$TD/scenes" --variants 0 --seed 18446744073709551615 -o "$T/bigseed" > /dev/null
rc=$?
ok '[ $rc -eq 0 ]' "--seed 2^64-1 accepted"
# --texture-bitmap 1 with a pool: the constant albedos swapped become pool images, recorded
"$DS" plan --scenes "$TD/scenes" --variants 1 --texture-swap 1 --texture-bitmap 1 \
  --texture-dir "$TD/../scenes/train-textures" --no-preview -o "$T/tb" > /dev/null
rc=$?
ok '[ $rc -eq 0 ] && grep -q "\"texture_bitmap\":	*1" "$T/tb/plan.json" &&
  grep -q "train-textures/" "$T/tb/scenes/cornell-box/v001.json" &&
  ! grep -q "checker" "$T/tb/scenes/cornell-box/v001.json"' "--texture-bitmap 1 puts pool images on constants"
# a finite strength so large that a perturbed value overflows: refused, naming the field
rm -rf "$T/bp"
"$DS" plan --scenes "$TD/scenes" --variants 2 --light 1e4 -o "$T/bp" > /dev/null 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && [ ! -e "$T/bp" ] && grep -q "made .* non-finite" "$T/err"' \
  "overflowing perturbation refused (rc $rc: $(cat "$T/err"))"
# a bad later scene: exit 1 naming the scene and field, and none of the earlier scene's files
mkdir -p "$T/bs/a" "$T/bs/b"
cp "$TD/scenes/cornell-box/scene.json" "$T/bs/a/"
sed '/"resolution": \[/,/\],/d' "$TD/scenes/cornell-box/scene.json" > "$T/bs/b/scene.json"
"$DS" plan --scenes "$T/bs" --variants 1 -o "$T/bsd" > /dev/null 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && [ ! -e "$T/bsd" ] && grep -q "scene .b.*no camera.resolution" "$T/err"' \
  "bad second scene leaves no output (rc $rc: $(cat "$T/err"))"
sed '/"resolution": \[/{n;s/32/1e12/;}' "$TD/scenes/cornell-box/scene.json" > "$T/bs/b/scene.json"
"$DS" plan --scenes "$T/bs" --variants 1 -o "$T/bsd" > /dev/null 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && [ ! -e "$T/bsd" ] && grep -q "scene .b.*camera.resolution 1000000000000 x 32" "$T/err"' \
  "scene resolution past 16384 refused (rc $rc: $(cat "$T/err"))"
# ... also when re-planning an existing dataset: its files stay as they were, nothing is added
rm -r "$T/bs/b"
"$DS" plan --scenes "$T/bs" --variants 1 -o "$T/bsd" > /dev/null
cp "$T/bsd/manifest.jsonl" "$T/bsd.m"
mkdir "$T/bs/b" && echo '{"camera": {' > "$T/bs/b/scene.json"
"$DS" plan --scenes "$T/bs" --variants 2 --force -o "$T/bsd" > /dev/null 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && cmp -s "$T/bsd.m" "$T/bsd/manifest.jsonl" && [ ! -e "$T/bsd/scenes/b" ] && [ ! -e "$T/bsd/scenes/a/v002.json" ]' \
  "failed re-plan leaves the dataset as it was (rc $rc: $(cat "$T/err"))"
# many variants: variants.jsonl keeps every line (a fixed buffer once kept the last ~545)
mkdir -p "$T/one" && ln -s "$TD/scenes/cornell-box" "$T/one/cornell-box"
"$DS" plan --scenes "$T/one" --variants 7000 --spp 2 --no-preview -o "$T/many" > /dev/null
rc=$?
vj="$T/many/scenes/cornell-box/variants.jsonl"
ok '[ $rc -eq 0 ] && [ $(wc -l < "$vj") -eq 7001 ] && head -1 "$vj" | grep -q "\"variant\":0," && tail -1 "$vj" | grep -q "\"variant\":7000,"' \
  "--variants 7000 lists 7001 variants (rc $rc, $(wc -l < "$vj") lines)"
rm -rf "$T/many"

# ---- manifest values are checked: exit 1 naming file, line and field ----
mkdir -p "$T/mf"
bad_manifest() { # SED-EXPR PATTERN DESC
  pat=$2
  sed "$1" "$T/d/manifest.jsonl" > "$T/mf/manifest.jsonl"
  "$DS" run "$T/mf" --list > /dev/null 2> "$T/err"
  rc=$?
  ok '[ $rc -eq 1 ] && grep -F -q -- "$pat" "$T/err"' "$3 (rc $rc: $(cat "$T/err"))"
}
bad_manifest '1s/"spp":[0-9]*/"spp":4.9/' 'manifest.jsonl:1: field "spp": 4.9 is not an integer' "fractional spp"
bad_manifest '2s/"seed":"[0-9]*"/"seed":"abc"/' "manifest.jsonl:2: field \"seed\": 'abc'" "non-numeric seed"
bad_manifest '1s/"seed":"[0-9]*"/"seed":"-1"/' "field \"seed\": '-1'" "negative seed"
bad_manifest '1s/"width":[0-9]*/"width":1e12/' 'field "width": 1000000000000 is not an integer' "huge width"
bad_manifest '1s/"variant":0/"variant":-7/' 'field "variant": -7' "negative variant"
bad_manifest '1s/}$/} garbage ]]/' "manifest.jsonl:1: not a JSON object" "text after the object"
{ printf '\n\n'; sed '1s/"spp":[0-9]*/"spp":0/' "$T/d/manifest.jsonl"; } > "$T/mf/manifest.jsonl"
"$DS" run "$T/mf" --list > /dev/null 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && grep -F -q "manifest.jsonl:3: field \"spp\": 0" "$T/err"' \
  "errors count blank lines ($(cat "$T/err"))"

# ---- shards partition the job list ----
"$DS" run "$T/d" --list > "$T/all"
: > "$T/union"
for i in 0 1 2; do "$DS" run "$T/d" --list --shard $i/3 >> "$T/union"; done
ok '[ $(wc -l < "$T/all") -eq 15 ]' "15 render jobs"
ok '[ "$(sort "$T/all")" = "$(sort "$T/union")" ]' "shards cover every job"
ok '[ -z "$(sort "$T/union" | uniq -d)" ]' "shards are disjoint"
for shard in 4294967296/4294967298 3/3 -1/3 " 1/3" 1/0 1/3/4; do
  "$DS" run "$T/d" --list --shard "$shard" > /dev/null 2> "$T/err"
  rc=$?
  ok '[ $rc -eq 2 ] && grep -q "for --shard" "$T/err"' "run --shard '$shard' refused (rc $rc)"
done
"$DS" run "$T/d" --shard 3/3 2> /dev/null
rc=$?
ok '[ $rc -eq 2 ]' "bad shard rejected"

# ---- resume after a killed run ----
export FAKE_LOG="$T/log1" FAKE_SLEEP=0.3
"$DS" run "$T/d" --jobs 2 --renderer "$FAKE" > /dev/null 2>&1 &
pid=$!
# stop it once a render has finished (polled: a fixed sleep was too short on a loaded machine)
i=0
while [ $i -lt 200 ] && [ -z "$(ls "$T"/d/renders/*/*.exr 2>/dev/null | grep -v part)" ]; do
  sleep 0.05
  i=$((i + 1))
done
kill -TERM $pid
wait $pid
rc=$?
ok '[ $rc -eq 143 ]' "a run stopped by SIGTERM exits 143 (got $rc)"
ls "$T"/d/renders/*/*.exr 2>/dev/null | grep -v part | sed "s|$T/d/||" | sort > "$T/done1"
n1=$(wc -l < "$T/done1")
ok '[ "$n1" -gt 0 ]' "some outputs after the kill ($n1)"
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
# stderr is a file here: whole progress lines (the first job's, then at most one a minute), and
# one after the last job
ok 'grep -Eq "^\[15/15\] rendered [0-9]+, running 0, failed 0, [0-9]+s elapsed, ~0s left$" "$T/run2.out"' \
  "a progress line after the last job (got: $(grep '^\[' "$T/run2.out" | tr '\n' '|'))"
ok '[ "$(grep -c "^\[" "$T/run2.out")" -le 3 ]' "at most a line a minute (and the first and last)"
sed -n 's|^start .*/d/||p' "$T/log2" | sort > "$T/started2"
ok '[ -z "$(comm -12 "$T/done1" "$T/started2")" ]' "resume re-rendered a finished output"
ok '[ $(ls "$T"/d/renders/*/*.exr | grep -v preview | wc -l) -eq 15 ]' "all 15 outputs exist"
nall=$(ls "$T"/d/renders/*/*.exr | grep -vc part)
ok '[ "$n1" -lt "$nall" ]' "the kill left some of the $nall outputs (previews included) to do ($n1 done)"
ok '[ -z "$(sort "$T/started2" | uniq -d)" ]' "a job started twice in one run"
export FAKE_LOG="$T/log3"
"$DS" run "$T/d" --jobs 2 --renderer "$FAKE" > "$T/run3.out" 2>&1
ok '[ ! -s "$T/log3" ] && grep -q "rendered 0, already done 15" "$T/run3.out"' "third run renders nothing"
# preview thresholds: fractions in [0, 1], a level > 0 (-1 used to reject every variant)
for bad in "--max-black -1" "--max-black nan" "--max-background 1.5" "--max-blown inf" \
           "--blown-level -inf" "--blown-level 0" "--progress-every -1" "--progress-every x"; do
  # shellcheck disable=SC2086
  "$DS" run "$T/d" --renderer "$FAKE" $bad > /dev/null 2> "$T/err"
  rc=$?
  ok '[ $rc -eq 2 ] && grep -F -q -- "for ${bad%% *}" "$T/err"' "run $bad refused (rc $rc: $(cat "$T/err"))"
done

# a renderer that exits 0 without writing its output: the job fails, saying so; a directory is
# not a renderer
"$DS" plan --scenes "$TD/scenes" --variants 0 --seed 3 --spp 2 --ref-spp 8 --no-preview \
  --split train:cornell-box+cornell-teal+cornell-wide -o "$T/t0" > /dev/null
"$DS" run "$T/t0" --jobs 1 --renderer /bin/true > /dev/null 2> "$T/err"
rc=$?
ok '[ $rc -ne 0 ] && grep -q "the renderer exited 0 without writing" "$T/err"' \
  "a renderer that writes nothing (rc $rc: $(head -n 2 "$T/err"))"
printf '#!/bin/sh\nwhile [ $# -gt 0 ]; do [ "$1" = -o ] && echo garbage > "$2"; shift; done\n' > "$T/garbage.sh"
chmod +x "$T/garbage.sh"
"$DS" run "$T/t0" --jobs 1 --renderer "$T/garbage.sh" > /dev/null 2> "$T/err"
rc=$?
ok '[ $rc -ne 0 ] && grep -q "is not a readable EXR" "$T/err" && [ -z "$(find "$T/t0/renders" -name "*.exr")" ]' \
  "a renderer that writes garbage: no job counts as done (rc $rc: $(head -n 1 "$T/err"))"
"$DS" run "$T/t0" --renderer "$T" > /dev/null 2> "$T/err"
rc=$?
ok '[ $rc -ne 0 ] && grep -q "is not an executable file" "$T/err"' "a directory as --renderer (rc $rc)"

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
# progress off a terminal: whole lines, the last pair's always (DESIGN §9), every pair's at 0 s
"$DS" patches "$T/r" --size 8 --per-image 5 -o "$T/r/prog.kps" > /dev/null 2> "$T/prog.err"
ok '[ "$(grep -c "^\[" "$T/prog.err")" -ge 1 ] && tail -n 1 "$T/prog.err" | grep -q "^\[10/10\] 50 patches kept, .*s elapsed, ~0s left$"' \
  "patches: a final progress line ($(tail -n 1 "$T/prog.err"))"
"$DS" patches "$T/r" --size 8 --per-image 5 -o "$T/r/prog.kps" --progress-every 0 > /dev/null 2> "$T/prog.err"
ok '[ "$(grep -c "^\[[0-9]*/10\] " "$T/prog.err")" -eq 10 ]' "patches --progress-every 0: a line per pair"
# a store that cannot be written (a file-size limit far below its 430 KB; SIGXFSZ ignored,
# so writes fail with EFBIG): exit 1 with the system's reason, not a guess, and no temporary
(trap '' XFSZ; ulimit -f 100 && exec "$DS" patches "$T/r" --size 8 --per-image 5 \
  -o "$T/r/fsz.kps") > /dev/null 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && grep -q "patch store .*fsz.kps.*: write failed: File too large" "$T/err" &&
  [ -z "$(ls "$T"/r/fsz.kps* 2> /dev/null)" ]' "patches over a file-size limit: its reason (rc $rc: $(cat "$T/err"))"
# session 60 (a review of the dataset pipeline): a NUL byte in the manifest cut it short
# silently, a job listed twice was cut into patches twice, an empty manifest was 0 jobs done,
# and renders left by an earlier plan (plan --force into the same folder, or a manifest edited
# since) were used as the new jobs' renders. Each is refused, naming the file and line or the
# render and its job.
"$DS" patches "$T/r" --size 8 --per-image 5 --cull 0 -o "$T/empty.kps" > /dev/null 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && [ ! -e "$T/empty.kps" ] && grep -q "no patch kept (.*all culled at --cull 0)" "$T/err"' \
  "a store of nothing refused (rc $rc: $(cat "$T/err"))"
rm -rf "$T/mf" && cp -r "$T/r" "$T/mf"
{ head -n 2 "$T/r/manifest.jsonl"; printf '\0'; tail -n +3 "$T/r/manifest.jsonl"; } >"$T/mf/manifest.jsonl"
"$DS" run "$T/mf" --list > /dev/null 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && grep -q "manifest.jsonl:3: a NUL byte" "$T/err"' "a NUL byte in the manifest (rc $rc: $(cat "$T/err"))"
{ cat "$T/r/manifest.jsonl"; head -n 1 "$T/r/manifest.jsonl"; } >"$T/mf/manifest.jsonl"
n=$(wc -l < "$T/mf/manifest.jsonl")
"$DS" patches "$T/mf" --size 8 --per-image 5 -o "$T/mf.kps" > /dev/null 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && [ ! -e "$T/mf.kps" ] && grep -q "is listed twice (lines 1 and $n)" "$T/err"' \
  "a job listed twice (rc $rc: $(cat "$T/err"))"
: >"$T/mf/manifest.jsonl"
"$DS" run "$T/mf" --renderer "$FAKE" > /dev/null 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && grep -q "holds no job" "$T/err"' "an empty manifest (rc $rc: $(cat "$T/err"))"
rm -rf "$T/mf" && cp -r "$T/r" "$T/mf"
"$DS" plan --scenes "$TD/scenes" --variants 2 --seed 4 --spp 2,4 --ref-spp 128 \
  --split train:cornell-box+cornell-teal,test:cornell-wide -o "$T/mf" --force > /dev/null
"$DS" run "$T/mf" --renderer "$FAKE" > /dev/null 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && grep -q "is not the render of job .*earlier plan (plan --force)" "$T/err"' \
  "run: renders of an earlier plan (rc $rc: $(cat "$T/err"))"
"$DS" patches "$T/mf" --size 8 --per-image 5 -o "$T/mf.kps" > /dev/null 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && [ ! -e "$T/mf.kps" ] && grep -q "is not the render of job" "$T/err"' \
  "patches: renders of an earlier plan (rc $rc: $(cat "$T/err"))"
# session 63: a re-plan whose variant scene files would change (an edited base scene, other
# perturbation strengths) kept the renders, and `run` took them as done (a render is matched to
# its job by size, spp and seed only). Without --force it is refused naming the file; with it,
# that variant's renders are removed and rendered again, the other variants' kept.
rm -rf "$T/cs" "$T/csd" && mkdir -p "$T/cs/a" && cp "$TD/scenes/cornell-box/scene.json" "$T/cs/a/"
"$DS" plan --scenes "$T/cs" --variants 1 --seed 3 --spp 2 --ref-spp 8 --no-preview -o "$T/csd" > /dev/null &&
  "$DS" run "$T/csd" --renderer "$FAKE" > /dev/null 2>&1
ok '[ -f "$T/csd/renders/a/v001_2spp.exr" ] && [ -f "$T/csd/renders/a/v000_2spp.exr" ]' "re-plan: first renders"
cp "$T/csd/renders/a/v000_2spp.exr" "$T/csd.v0"
"$DS" plan --scenes "$T/cs" --variants 1 --seed 3 --spp 2 --ref-spp 8 --no-preview --camera 3 \
  -o "$T/csd" --force > "$T/out" 2> "$T/err"
rc=$?
ok '[ $rc -eq 0 ] && grep -q "a/v001.s scene changed: 2 render file(s) removed" "$T/out" &&
  [ ! -e "$T/csd/renders/a/v001_2spp.exr" ] && [ ! -e "$T/csd/renders/a/v001_ref8spp.exr" ] &&
  cmp -s "$T/csd.v0" "$T/csd/renders/a/v000_2spp.exr"' \
  "re-plan --force with other strengths: the changed variant's renders removed, v000's kept (rc $rc: $(cat "$T/out" "$T/err"))"
"$DS" run "$T/csd" --renderer "$FAKE" > "$T/out" 2>&1
ok '[ -f "$T/csd/renders/a/v001_2spp.exr" ]' "re-plan: the removed variant rendered again ($(cat "$T/out"))"
sed 's/"fov": *\([0-9.]*\)/"fov": 31.5/' "$TD/scenes/cornell-box/scene.json" > "$T/cs/a/scene.json"
cp -r "$T/csd" "$T/csd.keep"
"$DS" plan --scenes "$T/cs" --variants 1 --seed 3 --spp 2 --ref-spp 8 --no-preview --camera 3 \
  -o "$T/csd" > /dev/null 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && grep -q "csd/scenes/a/v000.json. would change (the base scene .*--force" "$T/err" &&
  diff -r "$T/csd.keep" "$T/csd" > /dev/null' \
  "re-plan after the base scene was edited: refused, nothing changed (rc $rc: $(cat "$T/err"))"
# a render damaged after it was written (cut short): `run` takes it as done (its header
# matches), so `patches` names it and says how to make it again
f=$T/csd/renders/a/v001_2spp.exr
head -c $(($(wc -c < "$f") - 200)) "$f" > "$T/cut.exr" && mv "$T/cut.exr" "$f"
"$DS" patches "$T/csd" --size 8 --per-image 5 -o "$T/cs.kps" > /dev/null 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && [ ! -e "$T/cs.kps" ] && grep -q "truncated or corrupt.*remove .*v001_2spp.exr. and run .kpcn-dataset run. again" "$T/err"' \
  "patches: a render cut short is named with the remedy (rc $rc: $(cat "$T/err"))"
for order in "--per-image 5 --stride 4" "--stride 4 --per-image 5"; do
  # shellcheck disable=SC2086 # two options
  "$DS" patches "$T/r" --size 8 $order -o "$T/r/both.kps" 2> "$T/err"
  rc=$?
  ok '[ $rc -eq 2 ] && [ ! -e "$T/r/both.kps" ] && grep -q "exclude each other" "$T/err"' "--per-image with --stride refused ($order)"
done
"$DS" patches "$T/r" --size 8 --stride 4 -o "$T/r/grid.kps" > "$T/p.out"
ok '[ $? -eq 0 ] && grep -q ", 490 candidates" "$T/p.out"' "--stride: a 7x7 grid on 10 pairs ($(cat "$T/p.out"))"
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
# many directories (rule 56 merges 18): 20 copies of one directory give 20 times its pairs; 65
# are refused by name before anything is read
many=$(for i in $(seq 20); do cp -r "$T/d" "$T/d$i" && printf '%s ' "$T/d$i"; done)
# shellcheck disable=SC2086
np_many=$("$DS" patches $many --size 8 --per-image 5 -o "$T/many.kps" | sed 's/.*: \([0-9]*\) image pairs.*/\1/')
ok '[ -n "$np_many" ] && [ "$np_many" -eq $((20 * np_d)) ]' "20 directories: $np_many pairs = 20 x $np_d"
# shellcheck disable=SC2046
"$DS" patches $(for i in $(seq 65); do printf '%s ' "$T/d"; done) -o "$T/too.kps" 2> "$T/err"
rc=$?
ok '[ $rc -eq 2 ] && [ ! -e "$T/too.kps" ] && grep -q "more than 64 dataset directories" "$T/err"' \
  "65 directories refused (rc $rc: $(cat "$T/err"))"
# one directory twice (also through a link) would cut every pair twice: refused before any work
ln -s "$T/d" "$T/dlink"
"$DS" patches "$T/d" "$T/r" "$T/dlink" --size 8 --allow-partial -o "$T/twice.kps" 2> "$T/err"
rc=$?
ok '[ $rc -eq 2 ] && [ ! -e "$T/twice.kps" ] && grep -q "is given twice" "$T/err"' \
  "a directory given twice refused (rc $rc: $(cat "$T/err"))"
# the store may not replace a file it reads (the manifest, a render), nor be written where it
# cannot be (checked before the renders are read)
cp "$T/r/manifest.jsonl" "$T/manifest.bak"
for o in "$T/r/manifest.jsonl" "$T/r/renders/cornell-box/v000_2spp.exr" "$T/nodir/x.kps" "$T/r" \
  "$T/r/renders/cornell-wide/v000_4spp.exr" "$T/r/scenes/cornell-box/v001.json"; do
  "$DS" patches "$T/r" --size 8 --allow-partial -o "$o" 2> "$T/err"
  rc=$?
  ok '[ $rc -eq 2 ] && grep -Eq "is the same file as|folder .*nodir|is a directory" "$T/err"' \
    "patches -o $o refused (rc $rc: $(cat "$T/err"))"
done
ok 'cmp -s "$T/r/manifest.jsonl" "$T/manifest.bak" && [ -f "$T/r/renders/cornell-box/v000_2spp.exr" ] && grep -q "{" "$T/r/scenes/cornell-box/v001.json"' \
  "the manifest and the render are intact"
"$DS" patches "$T/r" "$T/nothing" --size 8 --allow-partial -o "$T/none.kps" 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && [ ! -e "$T/none.kps" ] && grep -q "nothing" "$T/err"' "a second directory without manifest"
"$DS" patches "$T/r" --size 64 --allow-partial -o "$T/r/big.kps" 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && [ ! -e "$T/r/big.kps" ] && grep -q "does not fit" "$T/err"' "patch larger than image"
# no pair because of the options, not the renders: said so, with what the manifest has
"$DS" patches "$T/r" --size 8 --spp 3 -o "$T/r/s3.kps" 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && [ ! -e "$T/r/s3.kps" ] && grep -q "no train render at --spp 3 (the train split.s noisy renders have spp 2,4)" "$T/err"' \
  "patches --spp 3 names the spp the split has (rc $rc: $(cat "$T/err"))"
"$DS" patches "$T/r" --size 8 --split nosuch -o "$T/r/s3.kps" 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && [ ! -e "$T/r/s3.kps" ] && grep -q "no noisy render in split .nosuch." "$T/err"' \
  "patches --split nosuch says the split is not planned (rc $rc: $(cat "$T/err"))"
# culling values must be finite (they go into the store's settings JSON)
for bad in "--cull inf" "--cull nan" "--cull-tol -1" "--cull-abs 1e999"; do
  # shellcheck disable=SC2086
  "$DS" patches "$T/r" --size 8 --allow-partial -o "$T/c.kps" $bad > /dev/null 2> "$T/err"
  rc=$?
  ok '[ $rc -eq 2 ] && [ ! -e "$T/c.kps" ] && grep -F -q -- "for ${bad%% *}" "$T/err"' \
    "patches $bad refused (rc $rc: $(cat "$T/err"))"
done
# any split name is safe in the settings JSON (it was pasted in unescaped)
rm -rf "$T/q" && cp -r "$T/r" "$T/q"
sed 's/"split":"train"/"split":"tr\\"ain"/' "$T/r/manifest.jsonl" > "$T/q/manifest.jsonl"
"$DS" patches "$T/q" --split 'tr"ain' --size 8 --per-image 2 --allow-partial -o "$T/q.kps" > /dev/null 2> "$T/err"
rc=$?
ok '[ $rc -eq 0 ] && grep -a -F -q "\"split\":\"tr\\\"ain\"" "$T/q.kps"' \
  "split name with a quote (rc $rc: $(cat "$T/err"))"
# --albedo-footprint: recorded in plan.json and on the noisy jobs only (a plan without it has
# neither), passed to the renderer for those jobs; a manifest value out of range is refused
"$DS" plan --scenes "$TD/scenes" --variants 1 --seed 3 --spp 2,4 --ref-spp 128 \
  --split train:cornell-box,val:cornell-teal,test:cornell-wide --albedo-footprint 2 \
  -o "$T/fp" > /dev/null
rc=$?
nfp=$(grep -c '"albedo_footprint":2' "$T/fp/manifest.jsonl")
nnoisy=$(grep -c '"kind":"noisy"' "$T/fp/manifest.jsonl")
ok '[ $rc -eq 0 ] && [ "$nfp" -eq "$nnoisy" ] && [ "$nnoisy" -gt 0 ] &&
    ! grep -v "\"kind\":\"noisy\"" "$T/fp/manifest.jsonl" | grep -q albedo_footprint &&
    grep -q "\"albedo_footprint\":[[:space:]]*2" "$T/fp/plan.json"' \
  "footprint on the noisy jobs only ($nfp of $nnoisy)"
ok '! grep -q albedo_footprint "$T/d/manifest.jsonl" "$T/d/plan.json"' "no footprint field without the option"
rm -f "$T/fp.log"
FAKE_LOG="$T/fp.log" "$DS" run "$T/fp" --jobs 2 --renderer "$FAKE" > /dev/null 2>&1
rc=$?
nlog=$(grep -c ' fp=2$' "$T/fp.log")
ok '[ $rc -eq 0 ] && [ "$nlog" -eq "$nnoisy" ] && ! grep " fp=" "$T/fp.log" | grep -q -v "spp.exr fp=2"' \
  "the renderer gets --albedo-footprint 2 for the noisy jobs ($nlog of $nnoisy)"
sed '0,/"albedo_footprint":2/s//"albedo_footprint":40/' "$T/fp/manifest.jsonl" > "$T/fp/m.tmp" &&
  mv "$T/fp/m.tmp" "$T/fp/manifest.jsonl"
"$DS" run "$T/fp" --renderer "$FAKE" > /dev/null 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && grep -q "albedo_footprint.*40 is not an integer in \[2, 16\]" "$T/err"' \
  "manifest footprint out of range refused (rc $rc: $(cat "$T/err"))"
"$DS" run "$T/nothing" 2> "$T/err"
rc=$?
ok '[ $rc -eq 1 ] && grep -q "manifest.jsonl" "$T/err"' "run without manifest"

# ---- one tiny real render ----
if [ -n "$REAL" ] && [ -x "$REAL" ]; then
  "$DS" plan --scenes "$TD/scenes" --variants 1 --seed 1 --spp 2 --ref-spp 8 --resolution 24x24 \
    --split train:cornell-box,val:cornell-teal,test:cornell-wide -o "$T/real" > /dev/null
  "$DS" run "$T/real" --jobs 2 --renderer "$REAL" > "$T/real.out" 2>&1
  rc=$?
  ok '[ $rc -eq 0 ]' "real render run ($(cat "$T/real.out"))"
  "$DS" patches "$T/real" --size 8 --per-image 4 -o "$T/real/train.kps" > /dev/null
  rc=$?
  ok '[ $rc -eq 0 ] && [ -s "$T/real/train.kps" ]' "real patches"
  # --checkpoint-every: a stopped run leaves its renders' checkpoints, the next run resumes
  # them to the bytes of a run never stopped, and no checkpoint stays behind
  for d in ck plain; do
    "$DS" plan --scenes "$TD/scenes" --variants 1 --seed 5 --spp 2 --ref-spp 2048 \
      --resolution 32x32 --no-preview --split train:cornell-box,val:cornell-teal,test:cornell-wide \
      -o "$T/$d" > /dev/null
  done
  "$DS" run "$T/ck" --jobs 1 --threads-per-job 1 --renderer "$REAL" --checkpoint-every 0.05 \
    > /dev/null 2>&1 &
  pid=$!
  for _ in $(seq 600); do # a reference render's (a 2-spp job's could end before the kill)
    [ -n "$(ls "$T"/ck/renders/*/*ref*.ckpt 2>/dev/null)" ] && break
    sleep 0.05
  done
  kill -TERM $pid
  wait $pid
  rc=$?
  ok '[ $rc -eq 143 ] && [ -n "$(ls "$T"/ck/renders/*/*.ckpt 2>/dev/null)" ]' \
    "a stopped run keeps its checkpoints (rc $rc)"
  "$DS" run "$T/ck" --dry-run > "$T/dry.out" 2>&1
  ok 'grep -q "^would render .*ref.* (a checkpoint is there)$" "$T/dry.out"' \
    "--dry-run names the jobs with a checkpoint"
  "$DS" run "$T/ck" --jobs 2 --renderer "$REAL" --checkpoint-every 0.05 > /dev/null 2>&1
  rc=$?
  ok 'grep -q "kpcn-render: resumed " "$T"/ck/logs/*ref*.log' "a job resumed (its log says so)"
  "$DS" run "$T/plain" --jobs 2 --renderer "$REAL" > /dev/null 2>&1
  rc=$((rc + $?))
  same=1
  # every channel's pixels (the headers name the scene files' different paths)
  for f in "$T"/plain/renders/*/*.exr; do
    idiff -fail 0 -warn 0 -a "$f" "$T/ck/${f#"$T"/plain/}" > /dev/null || same=0
  done
  ok '[ $rc -eq 0 ] && [ $same -eq 1 ] && [ -z "$(ls "$T"/ck/renders/*/*.ckpt 2>/dev/null)" ]' \
    "resumed renders equal uninterrupted ones; checkpoints removed"
elif [ -n "$REAL" ]; then
  ok 'false' "kpcn-render given as '$REAL' but not executable"
else
  echo "kpcn-render not built: real render part skipped"
fi
# ---- a stop signal during patches and run (docs/dataset.md: "SIGINT or SIGTERM between two
# pairs stops it with exit 128 + the signal and removes the unfinished store"; the store is
# written atomically, so a store already at -o stays as it was) ----
# Input slow enough to be stopped half-way: one plan of 256x256 renders (about 40 ms a pair),
# seen through 64 dataset directories that link to it (384 pairs, many seconds in all).
"$DS" plan --scenes "$TD/scenes" --variants 0 --seed 3 --spp 2,4 --ref-spp 128 --no-preview \
  --resolution 256x256 --split train:cornell-box+cornell-teal+cornell-wide -o "$T/sg" > /dev/null
FAKE_LOG=/dev/null FAKE_SLEEP=0 "$DS" run "$T/sg" --jobs 2 --renderer "$FAKE" > /dev/null 2>&1
rc=$?
ok '[ $rc -eq 0 ]' "signal test: the 256x256 dataset renders (rc $rc)"
sgdirs=""
for i in $(seq 64); do
  mkdir "$T/sg$i"
  for f in manifest.jsonl plan.json scenes renders; do ln -s "$T/sg/$f" "$T/sg$i/$f"; done
  sgdirs="$sgdirs $T/sg$i"
done
# signal_when SIG PID TRIES PAUSE CONDITION: while PID runs, evaluates CONDITION every PAUSE
# seconds, at most TRIES times, and sends SIG once it holds (sent=1; else sent=0 and PID is
# killed, never left running); then waits for PID (rc: its exit status)
signal_when() {
  sw_sig=$1 sw_pid=$2 sw_tries=$3 sw_pause=$4
  sent=0
  for _ in $(seq "$sw_tries"); do
    kill -0 "$sw_pid" 2> /dev/null || break
    if eval "$5"; then
      kill -"$sw_sig" "$sw_pid" && sent=1
      break
    fi
    sleep "$sw_pause"
  done
  [ $sent -eq 1 ] || kill -KILL "$sw_pid" 2> /dev/null
  wait "$sw_pid"
  rc=$?
}
# stop_patches SIG OUT CODE: start patches into OUT, send SIG once the temporary store exists
# and a first pair is done (the handler is installed by then; 20 s at most), wait; checks that
# the signal was sent while patches ran and that it exited CODE; sets sp_err (its stderr)
stop_patches() {
  sp_err="$T/sig_$1.err" sp_out=$2
  # shellcheck disable=SC2086 # the directories
  "$DS" patches $sgdirs --size 8 --per-image 2 --progress-every 0 -o "$2" > "$T/sig_$1.out" 2> "$sp_err" &
  signal_when "$1" $! 400 0.05 '[ -n "$(ls "$sp_out".tmp.* 2> /dev/null)" ] && grep -q "^\[1/" "$sp_err"'
  ok "[ $sent -eq 1 ]" "patches SIG$1: the signal was sent while patches ran (it had ended or \
never started writing first: rc $rc, $(tail -n 2 "$sp_err" | tr '\n' '|'))"
  ok "[ $rc -eq $3 ]" "patches stopped by SIG$1 exits $3 (got $rc)"
}
stop_patches TERM "$T/sig.kps" 143
ok '[ ! -e "$T/sig.kps" ] && [ -z "$(ls "$T"/sig.kps.* 2> /dev/null)" ]' \
  "patches SIGTERM: no store and no temporary left ($(cd "$T" && echo sig.kps*))"
ok 'grep -q "stopped by signal 15 after [0-9]* of 384 pairs; nothing written" "$sp_err" &&
  ! grep -q "stopped by signal 15 after 384 of" "$sp_err" && [ ! -s "$T/sig_TERM.out" ]' \
  "patches SIGTERM: stopped half-way, said so, no summary ($(grep stopped "$sp_err"))"
# SIGINT (^C) with a store already at -o: that store is kept as it was
cp "$T/r/train.kps" "$T/sig2.kps" && cp "$T/r/train.kps" "$T/sig2.bak"
stop_patches INT "$T/sig2.kps" 130
ok 'cmp -s "$T/sig2.kps" "$T/sig2.bak" && [ -z "$(ls "$T"/sig2.kps.* 2> /dev/null)" ]' \
  "patches SIGINT: the earlier store at -o intact, no temporary left ($(cd "$T" && echo sig2.kps*))"
ok 'grep -q "stopped by signal 2 after [0-9]* of 384 pairs; nothing written" "$sp_err"' \
  "patches SIGINT: said so ($(grep stopped "$sp_err"))"
rm -rf "$T"/sg*
# A signal during the last pair stops the run too (it used to be noticed only at the top of
# the next pair, so the store was finished and the exit was 0): three 1024x1024 pairs, the
# signal sent once the second is done, while the third (about a second) is read.
"$DS" plan --scenes "$TD/scenes" --variants 0 --seed 3 --spp 2 --ref-spp 128 --no-preview \
  --resolution 1024x1024 --split train:cornell-box+cornell-teal+cornell-wide -o "$T/sl" > /dev/null
FAKE_LOG=/dev/null FAKE_SLEEP=0 "$DS" run "$T/sl" --jobs 2 --renderer "$FAKE" > /dev/null 2>&1
"$DS" patches "$T/sl" --size 8 --per-image 2 --progress-every 0 -o "$T/sl.kps" > /dev/null 2> "$T/sl.err" &
signal_when TERM $! 1000 0.02 'grep -q "^\[2/3" "$T/sl.err"' # 20 s at most
ok '[ $sent -eq 1 ] && [ $rc -eq 143 ] && [ ! -e "$T/sl.kps" ] && [ -z "$(ls "$T"/sl.kps.* 2> /dev/null)" ]' \
  "patches SIGTERM during the last pair: exit 143, no store (sent $sent, rc $rc, $(tail -n 1 "$T/sl.err"))"
ok 'grep -q "stopped by signal 15 after [23] of 3 pairs; nothing written" "$T/sl.err"' "patches SIGTERM during the last pair: said so ($(grep stopped "$T/sl.err"))"
rm -rf "$T"/sl*
# run: SIGINT (^C) exits 130 and removes the part files (SIGTERM is checked above)
"$DS" plan --scenes "$TD/scenes" --variants 0 --seed 3 --spp 2 --ref-spp 128 --no-preview \
  --split train:cornell-box+cornell-teal+cornell-wide -o "$T/si" > /dev/null
FAKE_LOG="$T/logsi" FAKE_SLEEP=1 "$DS" run "$T/si" --jobs 2 --renderer "$FAKE" > /dev/null 2>&1 &
# once two renderers run (10 s at most)
signal_when INT $! 200 0.05 '[ -f "$T/logsi" ] && [ "$(grep -c "^start" "$T/logsi")" -ge 2 ]'
ok '[ $sent -eq 1 ] && [ $rc -eq 130 ]' "a run stopped by SIGINT exits 130 (sent $sent, got $rc)"
ok '[ -z "$(ls "$T"/si/renders/*/*.part* 2> /dev/null)" ]' "run SIGINT: no part file left"

echo "dataset_tool: $checks checks, $((checks-fails)) passed, $fails failed"
[ $fails -eq 0 ]
