# shellcheck shell=bash
# Every numeric option value of the four tools is parsed strictly (a table per tool, one row per
# numeric option of its --help; kpcntool's modifiers from docs/kpcntool.md): an empty value, a
# blank before or after it, a sign, trailing junk, hex, an exponent for an integer, a value that
# wraps a 32- or 64-bit integer onto a valid one (4294967312x4294967304 once rendered 16x8),
# one past 2^63, nan/inf/1e999 for a number, a negative one where none is allowed, and each of
# these in every item of a WxH / x,y,w,h / i/n / comma list, must be refused:
#   - kpcn-render, kpcn-dataset, kpcn-train: exit 2, the option named on stderr, no output;
#   - kpcntool: modifier values are checked when their command runs (kpcntool.md "Errors and
#     exit status"): exit 1, the modifier named after the echoed command, no -o file.
# Each row first runs once with its good value (which must succeed and write the output, so
# "no output" means something). The runs go in parallel, one folder each.
# usage: bash cli_option_values.sh KPCNTOOL KPCN_RENDER KPCN_TRAIN KPCN_DATASET TESTDATA WORKDIR
set -u
export LC_ALL=C
KT=$1 KR=$2 KTR=$3 KD=$4 TD=$5 WD=$6
rm -rf "$WD" && mkdir -p "$WD" && cd "$WD" || exit 1
WD=$PWD
SCENE=$TD/scenes/cornell-box/scene.json
NOISY=$TD/dataset/sample_noisy.exr
REF=$TD/dataset/sample_ref.exr
MODEL=$TD/models/kpcn-cpu.safetensors
FAKE=$TD/dataset/fake_render.sh
PAR=$(nproc 2>/dev/null || echo 2)
[ "$PAR" -ge 2 ] || PAR=2
[ "$PAR" -le 8 ] || PAR=8
P32=4294967296

# --- values -----------------------------------------------------------------------------------
# 2^64 + G as text, G < 290448384 (bash arithmetic ends at 2^63-1): what strtoull wraps to G
p64() { printf '18446744073%09d' $((709551616 + $1)); }
# bad_values KIND G [core]: the malformed variants of the good value G, in BAD. KIND: i+ an
# integer >= 0 (fits an int), i a signed one, s63 a seed in [0, 2^63-1], s64 a seed in
# [0, 2^64-1], f+ a finite number >= 0, f any finite number. "core": the short set kpcntool's
# modifiers of an already fully tested kind get (each kpcntool run costs ~0.2 s of loading).
bad_values() {
  local kind=$1 g=$2 set=${3:-full}
  case $kind:$set in
  i+:full | i:full | s63:full | s64:full)
    BAD=("" " $g" "$g " "+$g" "${g}x" 0x10 1e3 99999999999999999999 "$(p64 "$g")")
    case $kind in
    i+) BAD+=("$((g + P32))" 9223372036854775808 -1) ;;
    i) BAD+=("$((g + P32))" 9223372036854775808 "-$((P32 - g))") ;;
    s63) BAD+=(9223372036854775808 -1) ;;
    s64) BAD+=(-1) ;;
    esac
    ;;
  i+:core) BAD=("" " $g" "+$g" "$((g + P32))" -1) ;;
  i:core) BAD=("" " $g" "+$g" "$((g + P32))") ;;
  s63:core | s64:core) BAD=("" " $g" "$(p64 "$g")" -1) ;;
  f+:full | f:full)
    BAD=("" " $g" "$g " "${g}x" "$(printf %a "$g")" nan inf 1e999)
    if [ "$kind" = f+ ]; then BAD+=(-1); else BAD+=(-inf); fi
    ;;
  f+:core | f:core)
    BAD=("" " $g" "$(printf %a "$g")" nan)
    [ "$kind" = f ] || BAD+=(-1)
    ;;
  esac
  # values a row legitimately takes (SKIP, set by the caller for one row)
  local keep=() v s
  for v in "${BAD[@]}"; do
    for s in "${SKIP[@]}"; do [ "$v" = "$s" ] && continue 2; done
    keep+=("$v")
  done
  BAD=("${keep[@]}")
}
SKIP=()

# --- running ----------------------------------------------------------------------------------
# show CMD...: the command for a message, $TD and $WD abbreviated, odd values quoted
show() {
  local s=${1##*/} a
  shift
  for a in "$@"; do
    a=${a//"$TD"/\$TD}
    a=${a//"$WD"/\$WD}
    case $a in '' | *[!A-Za-z0-9_./:=,+@%\$-]*) a="'$a'" ;; esac
    s+=" $a"
  done
  printf '%s' "$s"
}
# names NAME FILE [STRIP]: FILE, less the first STRIP in it, names NAME (not inside a longer word)
names() {
  local t
  t=$(cat "$2")
  [ -z "${3:-}" ] || t=${t/"$3"/}
  case $1 in
  -*) printf '%s' "$t" | grep -qE -- "(^|[^A-Za-z0-9_-])$1([^A-Za-z0-9_-]|\$)" ;;
  *) printf '%s' "$t" | grep -qE -- "(^|[^A-Za-z0-9])$1([^A-Za-z0-9]|\$)" ;;
  esac
}
made() { [ -n "$(compgen -G "$1")" ]; }
# one_bad RCS NAME OUT STRIP CMD...: run in the case's folder (after $PREP), print one line
one_bad() {
  local rcs=$1 name=$2 out=$3 strip=$4 rc w m=no
  shift 4
  [ -z "$PREP" ] || $PREP
  timeout 60 "$@" >out.txt 2>err.txt </dev/null
  rc=$?
  w=$(show "$@")
  ! made "$out" || m=yes
  if [ $rc -eq 0 ]; then
    echo "FAIL: accepted (exit 0, output written: $m): $w"
  elif [[ " $rcs " != *" $rc "* ]]; then
    echo "FAIL: exit $rc (expected $rcs): $w: $(head -c 300 err.txt)"
  elif ! names "$name" err.txt "$strip"; then
    echo "FAIL: message does not name '$name': $w: $(head -c 300 err.txt)"
  elif [ $m = yes ]; then
    echo "FAIL: exit $rc but output '$out' written: $w"
  else
    echo "ok: exit $rc: $w"
  fi
}
one_good() {
  local out=$1 rc
  shift
  [ -z "$PREP" ] || $PREP
  timeout 60 "$@" >out.txt 2>err.txt </dev/null
  rc=$?
  if [ $rc -ne 0 ]; then
    echo "FAIL: good value refused (exit $rc): $(show "$@"): $(head -c 300 err.txt)"
  elif ! made "$out"; then
    echo "FAIL: good value wrote no '$out': $(show "$@")"
  else
    echo "ok: good: $(show "$@")"
  fi
}
n=0 running=0
PREP=
declare -A GOOD_DONE
spawn() {
  n=$((n + 1))
  mkdir "c$n"
  (cd "c$n" && "$@" >result 2>&1) &
  running=$((running + 1))
  if [ $running -ge "$PAR" ]; then
    wait -n
    running=$((running - 1))
  fi
}
# good OUT CMD...: must succeed and write OUT (a glob); each distinct command once
good() {
  local key="$*"
  [ -z "${GOOD_DONE[$key]:-}" ] || return 0
  GOOD_DONE[$key]=1
  spawn one_good "$@"
}
# bad RCS NAME OUT STRIP CMD...
bad() { spawn one_bad "$@"; }

# row BUILDER RCS OUT KIND OPT TEMPLATE G [core]: the option OPT's value is TEMPLATE with its
# '@' replaced by G (good) or by each bad variant of G. BUILDER OPT VALUE sets CMD and STRIP.
row() {
  local build=$1 rcs=$2 out=$3 kind=$4 opt=$5 tmpl=$6 g=$7 set=${8:-full} v
  local pre=${tmpl%%@*} post=${tmpl#*@}
  $build "$opt" "$pre$g$post"
  good "$out" "${CMD[@]}"
  bad_values "$kind" "$g" "$set"
  for v in "${BAD[@]}"; do
    $build "$opt" "$pre$v$post"
    bad "$rcs" "${NAME:-$opt}" "$out" "$STRIP" "${CMD[@]}"
  done
  SKIP=()
}
# literal BUILDER RCS OUT OPT VALUE...: these exact values are refused
literal() {
  local build=$1 rcs=$2 out=$3 opt=$4 v
  shift 4
  for v in "$@"; do
    $build "$opt" "$v"
    bad "$rcs" "${NAME:-$opt}" "$out" "$STRIP" "${CMD[@]}"
  done
}

# --- fixtures: a planned dataset (fake renders, 3 scenes, 32x32), its patch store, a model ------
"$KD" plan --scenes "$TD/dataset/scenes" -o plan0 --variants 0 --spp 4 --ref-spp 256 --no-preview \
  >/dev/null 2>&1 && cp -r plan0 ds &&
  "$KD" run ds --renderer "$FAKE" --jobs 1 >/dev/null 2>&1 &&
  "$KD" patches ds -o p.kps --size 16 --per-image 2 --cull 2 >/dev/null 2>&1 &&
  "$KTR" --store p.kps -o m0.safetensors --preset tiny --iters 1 --batch 1 --patch 16 --threads 1 \
    --quiet --ckpt '' --csv '' --plot '' >/dev/null 2>&1 || {
  echo "FAIL: fixtures (plan, run, patches, train) could not be made"
  exit 1
}
STRIP=

# --- kpcn-render ------------------------------------------------------------------------------
b_render() {
  local o=$1
  CMD=("$KR" "$SCENE" -o out.exr --quiet)
  [ "$o" = --resolution ] || CMD+=(--resolution 8x8)
  [ "$o" = --spp ] || CMD+=(--spp 1)
  case $o in --checkpoint-every | --time-limit) CMD+=(--checkpoint ck) ;; esac
  CMD+=("$o" "$2")
}
r() { row b_render 2 out.exr "$@"; }
r i+ --spp @ 1
r s63 --seed @ 1
r i+ --threads @ 1
r i+ --albedo-spp @ 2
r i+ --albedo-footprint @ 2
r i+ --max-bounces @ 2
r f+ --checkpoint-every @ 5
r f+ --time-limit @ 5
r i+ --resolution @x8 8
r i+ --resolution 8x@ 8
r i+ --crop @,0,4,4 0
r i+ --crop 0,@,4,4 0
r i+ --crop 0,0,@,4 4
r i+ --crop 0,0,4,@ 4
literal b_render 2 out.exr --resolution 8x8x8 x8 8x 8 8X8 "8 x8" "8x 8" 4294967312x4294967304
literal b_render 2 out.exr --crop 0,0,4 0,0,4,4, ,0,0,4,4 0,0,4,4,4 "0, 0,4,4" 0,,4,4

# --- kpcn-dataset plan ------------------------------------------------------------------------
b_plan() {
  local o=$1
  CMD=("$KD" plan --scenes "$TD/dataset/scenes" -o pl --no-preview)
  [ "$o" = --variants ] || CMD+=(--variants 0)
  [ "$o" = --resolution ] || CMD+=(--resolution 8x8)
  [ "$o" = --spp ] || CMD+=(--spp 4)
  [ "$o" = --ref-spp ] || CMD+=(--ref-spp 8)
  CMD+=("$o" "$2")
}
p() { row b_plan 2 pl "$@"; }
p i+ --variants @ 1
p s64 --seed @ 1
p i+ --ref-spp @ 8
p i+ --preview-spp @ 4
p i+ --preview-scale @ 4
p i+ --albedo-footprint @ 2
for o in --camera --fov --material --light --env; do p f+ $o @ 1; done
for o in --bsdf-swap --texture-swap --texture-bitmap; do p f+ $o @ 0.5; done
p i+ --resolution @x8 8
p i+ --resolution 8x@ 8
p i+ --spp @,8 4
p i+ --spp 4,@ 8
p f+ --split train:@,val:0.5 0.5
p f+ --split train:0.5,val:@ 0.5
literal b_plan 2 pl --resolution 8x8x8 x8 8x 8 "8 x8" 4294967312x4294967304
literal b_plan 2 pl --spp ,4 4, 4,,8 "4, 8" "4 ,8" 4294967300
literal b_plan 2 pl --split "train:0.5,val: 0.5" "train:0.5,val:0.5 "

# --- kpcn-dataset run (on a copy of the planned, unrendered dataset; the fake renderer) ---------
copy_plan() { cp -r "$WD/plan0" ds; }
b_run() {
  CMD=("$KD" run ds --renderer "$FAKE")
  [ "$1" = --jobs ] || CMD+=(--jobs 1)
  CMD+=("$1" "$2")
}
PREP=copy_plan
u() { row b_run 2 'ds/renders/*/*.exr' "$@"; }
u i+ --jobs @ 1
u i+ --threads-per-job @ 1
u f+ --checkpoint-every @ 5
u f+ --progress-every @ 5
u i+ --shard @/1 0
u i+ --shard 0/@ 1
for o in --max-black --max-background --max-blown; do u f+ $o @ 0.5; done
u f+ --blown-level @ 1
literal b_run 2 'ds/renders/*/*.exr' --shard 0/1/1 /1 0/ 0 "0 /1" "0/ 1" 4294967296/1 0/4294967297
PREP=

# --- kpcn-dataset patches ---------------------------------------------------------------------
b_patches() {
  local o=$1
  CMD=("$KD" patches "$WD/ds" -o p.kps --allow-partial)
  [ "$o" = --size ] || CMD+=(--size 16)
  [ "$o" = --per-image ] || [ "$o" = --stride ] || CMD+=(--per-image 2)
  CMD+=("$o" "$2")
}
q() { row b_patches 2 p.kps "$@"; }
q i+ --size @ 16
q i+ --per-image @ 2
q i+ --stride @ 16
for o in --cull --cull-tol --cull-abs; do q f+ $o @ 0.5; done
q f+ --progress-every @ 5
q i+ --seed @ 1
q i+ --spp @ 4
q i+ --spp 4,@ 8
literal b_patches 2 p.kps --spp ,4 4, 4,,8 "4, 8" 4294967300

# --- kpcn-train -------------------------------------------------------------------------------
b_train() {
  local o=$1
  CMD=("$KTR" --store "$WD/p.kps" -o m.safetensors --preset tiny --quiet --ckpt '' --csv '' --plot '')
  [ "$o" = --iters ] || CMD+=(--iters 1)
  [ "$o" = --batch ] || CMD+=(--batch 1)
  [ "$o" = --patch ] || CMD+=(--patch 16)
  [ "$o" = --threads ] || CMD+=(--threads 1)
  case $o in
  --widen) CMD+=(--init "$WD/m0.safetensors") ;;
  --ssim-window) CMD+=(--loss ssim) ;;
  --source-lr-scale) CMD+=(--source-weight) ;;
  esac
  CMD+=("$o" "$2")
}
t() { row b_train 2 m.safetensors "$@"; }
t i+ --layers @ 2
t i+ --channels @ 4
t i+ --widen @ 16
t i+ --kpa-passes @ 1
t i+ --conv @ 3
t i+ --kernel @ 5
t i+ --ssim-window @ 5
t i+ --loss-margin @ 2
t i+ --batch @ 1
t i+ --patch @ 16
t i+ --iters @ 1
t i+ --stage1-iters @ 1
t i+ --threads @ 1
t s63 --seed @ 1
t i+ --val-every @ 1
t i+ --ckpt-every @ 1
t i+ --log-every @ 1
t i+ --decay-every @ 100
t f+ --source-lr-scale @ 2
t f+ --firefly @ 4
t f+ --lr @ 0.001
t f+ --eps @ 0.01
t f+ --lr2 @ 0.001
t f+ --lr-decay @ 0.96
t f+ --clip @ 1
t f+ --time-limit @ 5
t i+ --dilations @,1 2
t i+ --dilations 1,@ 2
literal b_train 2 m.safetensors --dilations ,1 1, 1,,1 "1, 1" 4294967298
b_seteps() { CMD=("$KTR" --set-eps e.safetensors "$WD/m0.safetensors" "$2"); }
row b_seteps 2 e.safetensors f+ --set-eps @ 0.01

# --- kpcntool ---------------------------------------------------------------------------------
# KPRE (images) HEAD:KEY=VALUE KPOST -o out.exr; the message must name KEY after the echoed
# command (which repeats every modifier).
b_kt() {
  CMD=("$KT" "${KPRE[@]}" "$HEAD:$1=$2" "${KPOST[@]}" -o out.exr)
  STRIP="$HEAD:$1=$2"
}
k() { row b_kt 1 out.exr "$@"; }
KPOST=()
KPRE=("$NOISY" "$REF")
HEAD=--augment
k s64 seed @ 1
k s64 index @ 0 core
k i+ shift @ 2 core
KPRE=("$NOISY")
HEAD=--colormap
SKIP=("") # max= (empty): the 99th percentile, as without it
k f+ max @ 1 core
HEAD=--denoise:model=$MODEL
k i+ tile @ 16 core
k i+ ensemble @ 2 core
k f+ exposure @ 0.5
k f+ firefly @ 4
HEAD=--kernels:model=$MODEL # kpcntool.md: bf16, tile, exposure, firefly "as --denoise"
k i+ tile @ 16 core
k f+ exposure @ 0.5 core
k f+ firefly @ 4 core
KPRE=("$NOISY" "$REF")
HEAD=--l1
k f+ range @ 1
k f+ eps @ 0.01 core
for c in mse relmse rell1 psnr ssim errormap; do # kpcntool.md: the same modifiers as --l1
  SKIP=("" -1 nan)
  HEAD=--$c
  k f+ range @ 1 core
  SKIP=("" -1 nan)
  k f+ eps @ 0.01 core
done
HEAD=--mosaic
k i+ n @ 2 core
k i+ fontsize @ 16 core
HEAD=--patches:count=2
k i+ size @ 16
HEAD=--patches:size=16
k i+ count @ 2 core
k i+ stride @ 16 core
HEAD=--patches:size=16:count=2
k s64 seed @ 1 core
k f+ cull @ 0.5 core
k f+ tol @ 0.05 core
k f+ abs @ 0.01 core
KPRE=()
KPOST=("$SCENE")
HEAD=--render:res=8x8
k i+ spp @ 1 core
HEAD=--render:res=8x8:spp=1
k s63 seed @ 1
k i+ albedo_spp @ 2 core
k i+ footprint @ 2 core
k i max_bounces @ 2 core # -1: the scene's
HEAD=--render:spp=1
k i+ res @x8 8
k i+ res 8x@ 8
HEAD=--render:res=8x8:spp=1
k i+ crop @,0,4,4 0
k i+ crop 0,@,4,4 0 core
k i+ crop 0,0,@,4 4 core
k i+ crop 0,0,4,@ 4 core
literal b_kt 1 out.exr crop 0,0,4 0,0,4,4, "0, 0,4,4" 4294967296,0,4,4
literal b_kt 1 out.exr max_bounces -2
HEAD=--render:res=8x8:spp=1:max_bounces=2
literal b_kt 1 out.exr res 8x8x8 8 "8 x8" 4294967304x4294967304
KPOST=()
KPRE=("$NOISY")
HEAD=--rotate
k f deg @ 90 core
HEAD=--shift
k i dx @ 1
k i dy @ 1 core
# 0|1 switches: exactly "0" or "1"
for s in "--mirror all" "--augment oneof" "--augment mirror_v" "--denoise:model=$MODEL bf16" \
  "--render:res=8x8:spp=1 color_only" "--l1 allow_nonfinite" "--patches:size=16:count=2 importance"; do
  HEAD=${s% *}
  KPRE=("$NOISY" "$REF") KPOST=()
  case $HEAD in --render*) KPRE=() KPOST=("$SCENE") ;; esac
  b_kt "${s##* }" 1
  good out.exr "${CMD[@]}"
  literal b_kt 1 out.exr "${s##* }" " 1" "+1"
done
# --threads N and --ch's constants are arguments, not modifiers (exit 1 or 2)
STRIP=
b_threads() { CMD=("$KT" --threads "$2" "$NOISY" -o out.exr); }
NAME="thread count"
row b_threads "1 2" out.exr i+ --threads @ 1 core
b_ch() { CMD=("$KT" "$REF" --ch "R,G,B,A=$2" -o out.exr); }
NAME=constant
row b_ch "1 2" out.exr f --ch @ 1 core
NAME=

wait
ok=0 fails=0
for i in $(seq 1 $n); do
  if grep -q '^ok' "c$i/result"; then
    ok=$((ok + 1))
  else
    cat "c$i/result"
    fails=$((fails + 1))
  fi
done
echo "cli_option_values: $ok checks passed, $fails failed"
[ $fails -eq 0 ]
