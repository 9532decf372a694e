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
# Each row's good value must succeed and write the output (so "no output" means something;
# kpcntool's run together in four command lines), and every numeric option of each --help
# (kpcntool: every modifier that takes a number) must have a row. The runs go in parallel.
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
# bad_values KIND G [short]: the malformed variants of the good value G, in BAD. KIND: i+ an
# integer >= 0 (fits an int), i a signed one, l+ an integer >= 0 whose range passes 2^32,
# s63 a seed in [0, 2^63-1], s64 a seed in [0, 2^64-1], f+ a finite number >= 0, f any
# finite number. "short": for kpcntool's modifiers of a kind tested in full elsewhere, the
# values strtol/strtod/strtoull take that a strict parser must not (a blank, a sign, hex, a
# 32- or 64-bit wrap).
bad_values() {
  local kind=$1 g=$2 set=${3:-full}
  case $kind:$set in
  i+:full | i:full | l+:full | s63:full | s64:full)
    BAD=("" " $g" "$g " "+$g" "${g}x" 0x10 1e3 99999999999999999999 "$(p64 "$g")")
    case $kind in
    i+) BAD+=("$((g + P32))" 9223372036854775808 -1) ;;
    i) BAD+=("$((g + P32))" 9223372036854775808 "-$((P32 - g))") ;;
    l+ | s63) BAD+=(9223372036854775808 -1) ;;
    s64) BAD+=(-1) ;;
    esac
    ;;
  i+:short | i:short) BAD=(" $g" "+$g" "$((g + P32))") ;;
  s63:short | s64:short) BAD=(" $g" "$(p64 "$g")") ;;
  f+:full | f:full)
    BAD=("" " $g" "$g " "${g}x" "$(printf %a "$g")" nan inf 1e999)
    if [ "$kind" = f+ ]; then BAD+=(-1); else BAD+=(-inf); fi
    ;;
  f+:short | f:short) BAD=(" $g" "$(printf %a "$g")") ;;
  esac
}

# --- running ----------------------------------------------------------------------------------
# (No command substitutions below: ~1300 cases, each fork costs.)
# show CMD...: W = the command for a message, $TD and $WD abbreviated, odd values quoted
show() {
  local a
  W=${1##*/}
  shift
  for a in "$@"; do
    a=${a//"$TD"/\$TD}
    a=${a//"$WD"/\$WD}
    case $a in '' | *[!A-Za-z0-9_./:=,+@%\$-]*) a="'$a'" ;; esac
    W+=" $a"
  done
}
# err ID: E = the case's stderr (its start)
err() {
  E=
  IFS= read -r -d '' E <"e$1"
  E=${E:0:300}
}
# names NAME FILE [STRIP]: FILE, less the first STRIP in it, names NAME (not inside a longer word:
# for an option, not --spp in --ref-spp; for a kpcntool modifier, not spp in albedo_spp)
names() {
  local t='' b=A-Za-z0-9 re
  IFS= read -r -d '' t <"$2"
  [ -z "${3:-}" ] || t=${t/"$3"/}
  [[ $1 != -* ]] || b="A-Za-z0-9_-"
  re="(^|[^$b])$1([^$b]|\$)"
  [[ $t =~ $re ]]
}
made() { [ -n "$1" ] && compgen -G "$1" >/dev/null; }
# args ID ARG...: A = ARGS with every @@ replaced by the case number ID (the case's file names)
args() {
  local id=$1 a
  shift
  A=()
  for a in "$@"; do A+=("${a//@@/$id}"); done
}
# one_bad ID RCS NAME OUT STRIP CMD...: print one line (ok or FAIL) for a value to refuse
one_bad() {
  local id=$1 rcs=$2 name=$3 out=${4//@@/$1} strip=$5 rc m=no
  shift 5
  args "$id" "$@"
  timeout 20 "${A[@]}" >/dev/null 2>"e$id" </dev/null
  rc=$?
  show "${A[@]}"
  ! made "$out" || m=yes
  if [ $rc -eq 0 ]; then
    echo "FAIL: accepted (exit 0, output written: $m): $W"
  elif [[ " $rcs " != *" $rc "* ]]; then
    err "$id"
    echo "FAIL: exit $rc (expected $rcs): $W: $E"
  elif ! names "$name" "e$id" "${strip//@@/$id}"; then
    err "$id"
    echo "FAIL: message does not name '$name': $W: $E"
  elif [ $m = yes ]; then
    echo "FAIL: exit $rc but output '$out' written: $W"
  else
    echo "ok: exit $rc: $W"
  fi
}
# one_good ID OUT CMD...: the command succeeds and writes OUT
one_good() {
  local id=$1 out=${2//@@/$1} rc
  shift 2
  args "$id" "$@"
  timeout 20 "${A[@]}" >/dev/null 2>"e$id" </dev/null
  rc=$?
  show "${A[@]}"
  if [ $rc -ne 0 ]; then
    err "$id"
    echo "FAIL: good value refused (exit $rc): $W: $E"
  elif [ -n "$out" ] && ! made "$out"; then
    echo "FAIL: good value wrote no '$out': $W"
  else
    echo "ok: good: $W"
  fi
}
# Every case runs in the background (PAR at once) in this folder; its files are named with its
# number (@@ in the command): a folder per case made the test slow on a busy disk.
n=0 running=0
NOGOOD='' TOOL=''
declare -A TESTED # "TOOL OPTION" (kpcntool: "kpcntool --COMMAND MODIFIER") of every row
declare -A GOOD_DONE
spawn() {
  local f=$1
  shift
  n=$((n + 1))
  $f $n "$@" >"r$n" 2>&1 &
  running=$((running + 1))
  if [ $running -ge "$PAR" ]; then
    wait -n
    running=$((running - 1))
  fi
  return 0
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

# row BUILDER RCS OUT KIND OPT TEMPLATE G [short]: the option OPT's value is TEMPLATE with its
# '@' replaced by G (good) or by each bad variant of G. BUILDER OPT VALUE sets CMD and STRIP;
# OUT ('' = none), CMD and STRIP name the case's files with @@.
row() {
  local build=$1 rcs=$2 out=$3 kind=$4 opt=$5 tmpl=$6 g=$7 set=${8:-full} v
  local pre=${tmpl%%@*} post=${tmpl#*@}
  TESTED["$TOOL $opt"]=1
  $build "$opt" "$pre$g$post"
  [ -n "$NOGOOD" ] || good "$out" "${CMD[@]}"
  bad_values "$kind" "$g" "$set"
  for v in "${BAD[@]}"; do
    $build "$opt" "$pre$v$post"
    bad "$rcs" "${NAME:-$opt}" "$out" "$STRIP" "${CMD[@]}"
  done
}
# literal BUILDER RCS OUT OPT VALUE...: these exact values are refused
literal() {
  local build=$1 rcs=$2 out=$3 opt=$4 v
  shift 4
  TESTED["$TOOL $opt"]=1
  for v in "$@"; do
    $build "$opt" "$v"
    bad "$rcs" "${NAME:-$opt}" "$out" "$STRIP" "${CMD[@]}"
  done
}

# --- fixtures: a planned dataset (fake renders, 3 scenes, 32x32), its patch store, a model ------
if ! { "$KD" plan --scenes "$TD/dataset/scenes" -o plan0 --variants 0 --spp 4 --ref-spp 256 \
  --no-preview && cp -r plan0 ds && "$KD" run ds --renderer "$FAKE" --jobs 1 &&
  "$KD" patches ds -o p.kps --size 16 --per-image 2 --cull 2 &&
  "$KTR" --store p.kps -o m0.safetensors --preset tiny --iters 1 --batch 1 --patch 16 \
    --threads 1 --quiet --ckpt '' --csv '' --plot ''; } >fixtures.log 2>&1; then
  echo "FAIL: fixtures (plan, run, patches, train) could not be made: $(cat fixtures.log)"
  exit 1
fi
STRIP=

# Tables: one row per option value, "KIND OPTION TEMPLATE GOOD" (kinds: bad_values; a list's
# TEMPLATE holds each item in turn as @), then literal malformed lists.
# --- kpcn-render ------------------------------------------------------------------------------
TOOL=kpcn-render
b_render() {
  local o=$1
  CMD=("$KR" "$SCENE" -o o@@.exr --quiet)
  [ "$o" = --resolution ] || CMD+=(--resolution 8x8)
  [ "$o" = --spp ] || CMD+=(--spp 1)
  case $o in --checkpoint-every | --time-limit) CMD+=(--checkpoint ck@@) ;; esac
  CMD+=("$o" "$2")
}
r() { row b_render 2 o@@.exr "$@"; }
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
literal b_render 2 o@@.exr --resolution 8x8x8 x8 8x 8 8X8 "8 x8" "8x 8" 4294967312x4294967304
literal b_render 2 o@@.exr --crop 0,0,4 0,0,4,4, ,0,0,4,4 0,0,4,4,4 "0, 0,4,4" 0,,4,4

# --- kpcn-dataset plan ------------------------------------------------------------------------
TOOL="kpcn-dataset plan"
b_plan() {
  local o=$1
  CMD=("$KD" plan --scenes "$TD/dataset/scenes" -o pl@@ --no-preview)
  [ "$o" = --variants ] || CMD+=(--variants 0)
  [ "$o" = --resolution ] || CMD+=(--resolution 8x8)
  [ "$o" = --spp ] || CMD+=(--spp 4)
  [ "$o" = --ref-spp ] || CMD+=(--ref-spp 8)
  CMD+=("$o" "$2")
}
p() { row b_plan 2 pl@@ "$@"; }
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
literal b_plan 2 pl@@ --resolution 8x8x8 x8 8x 8 "8 x8" 4294967312x4294967304
literal b_plan 2 pl@@ --spp ,4 4, 4,,8 "4, 8" "4 ,8" 4294967300
literal b_plan 2 pl@@ --split "train:0.5,val:0.5 " "train:0.5, val:0.5"

# --- kpcn-dataset run (--dry-run on the planned dataset: a value taken shows as exit 0) --------
TOOL="kpcn-dataset run"
b_run() {
  CMD=("$KD" run "$WD/plan0" --dry-run --renderer "$FAKE")
  [ "$1" = --jobs ] || CMD+=(--jobs 1)
  CMD+=("$1" "$2")
}
u() { row b_run 2 '' "$@"; }
u i+ --jobs @ 1
u i+ --threads-per-job @ 1
u f+ --checkpoint-every @ 5
u f+ --progress-every @ 5
u i+ --shard @/1 0
u i+ --shard 0/@ 1
for o in --max-black --max-background --max-blown; do u f+ $o @ 0.5; done
u f+ --blown-level @ 1
literal b_run 2 '' --shard 0/1/1 /1 0/ 0 "0 /1" "0/ 1" 4294967296/1 0/4294967297

# --- kpcn-dataset patches ---------------------------------------------------------------------
TOOL="kpcn-dataset patches"
b_patches() {
  local o=$1
  CMD=("$KD" patches "$WD/ds" -o p@@.kps --allow-partial)
  [ "$o" = --size ] || CMD+=(--size 16)
  [ "$o" = --per-image ] || [ "$o" = --stride ] || CMD+=(--per-image 2)
  CMD+=("$o" "$2")
}
q() { row b_patches 2 p@@.kps "$@"; }
q i+ --size @ 16
q i+ --per-image @ 2
q i+ --stride @ 16
for o in --cull --cull-tol --cull-abs; do q f+ $o @ 0.5; done
q f+ --progress-every @ 5
q i+ --seed @ 1
q i+ --spp @ 4
q i+ --spp 4,@ 8
literal b_patches 2 p@@.kps --spp ,4 4, 4,,8 "4, 8" 4294967300

# --- kpcn-train -------------------------------------------------------------------------------
TOOL=kpcn-train
b_train() {
  local o=$1
  CMD=("$KTR" --store "$WD/p.kps" -o m@@.safetensors --preset tiny --quiet --ckpt '' --csv ''
    --plot '')
  [ "$o" = --iters ] || CMD+=(--iters 1)
  [ "$o" = --batch ] || CMD+=(--batch 1)
  [ "$o" = --patch ] || CMD+=(--patch 16)
  [ "$o" = --threads ] || CMD+=(--threads 1)
  case $o in
  --widen) CMD+=(--init "$WD/m0.safetensors") ;;
  --ssim-window) CMD+=(--loss ssim) ;;
  --source-lr-scale) CMD+=(--source-weight) ;;
  --val-every) CMD+=(--val "$NOISY,$REF") ;; # without validation images it has no effect
  esac
  CMD+=("$o" "$2")
}
t() { row b_train 2 m@@.safetensors "$@"; }
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
t l+ --iters @ 1
t l+ --stage1-iters @ 1
t i+ --threads @ 1
t s63 --seed @ 1 # 0 .. 9e18
t l+ --val-every @ 1
t l+ --ckpt-every @ 1
t l+ --log-every @ 1
t l+ --decay-every @ 100
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
literal b_train 2 m@@.safetensors --dilations ,1 1, 1,,1 "1, 1" 4294967298
b_seteps() { CMD=("$KTR" --set-eps x@@.safetensors "$WD/m0.safetensors" "$2"); }
row b_seteps 2 x@@.safetensors f+ --set-eps @ 0.01

# --- kpcntool ---------------------------------------------------------------------------------
TOOL=kpcntool
# KPRE (images) HEAD:KEY=VALUE KPOST -o o@@.exr; the message must name KEY after the echoed
# command (which repeats every modifier). A kpcntool run costs ~0.15 s of CPU (loading its
# libraries), so the full set goes to one modifier of each kind kpcntool.md names (an integer,
# a number, a seed, the render seed, res, exposure/firefly with their words) and every other
# modifier gets the short set; those kpcntool.md says are shared (the metrics' with --l1's,
# --kernels' with --denoise's) one value each; the good values run together in four lines.
b_kt() {
  TESTED["kpcntool ${HEAD%%:*} $1"]=1
  CMD=("$KT" "${KPRE[@]}" "$HEAD:$1=$2" "${KPOST[@]}" -o o@@.exr)
  STRIP="$HEAD:$1=$2"
}
k() { row b_kt 1 o@@.exr "$@"; }
kl() { literal b_kt 1 o@@.exr "$@"; }
NOGOOD=1
D=--denoise:model=$MODEL
P=--patches:size=16:count=2
good o@@.exr "$KT" "$NOISY" "$REF" --augment:seed=1:index=0:shift=2 --augment:oneof=1 \
  --augment:mirror_v=1 --mirror:all=1 --l1:range=1:eps=0.01:allow_nonfinite=1 \
  --mse:range=1:eps=0.01 --relmse:range=1:eps=0.01 --rell1:range=1:eps=0.01 \
  --psnr:range=1:eps=0.01 --ssim:range=1:eps=0.01 "$P:seed=1:cull=0.5:tol=0.05:abs=0.01:importance=1" \
  --patches:size=16:stride=16 --patches:count=2:size=16 --errormap:range=1:eps=0.01 -o o@@.exr
good o@@.exr "$KT" "$NOISY" "$REF" --mosaic:n=2:fontsize=16 --colormap:max=1 --rotate:deg=90 \
  --shift:dx=1:dy=1 -o o@@.exr
good o@@.exr "$KT" --threads 1 "$NOISY" "$D:tile=16:ensemble=2:exposure=0.5:firefly=4:bf16=1" \
  "$NOISY" "--kernels:model=$MODEL:tile=16:exposure=0.5:firefly=4" "$REF" --ch R,G,B,A=1 -o o@@.exr
good o@@.exr "$KT" --render:res=8x8:spp=1:seed=1:albedo_spp=2:footprint=2:max_bounces=2 \
  "$SCENE" --render:spp=1:res=8x8:crop=0,0,4,4:color_only=1 "$SCENE" -o o@@.exr
KPOST=()
KPRE=("$NOISY" "$REF")
HEAD=--augment
kl seed "" " 1" "+1" 99999999999999999999 "$(p64 1)" -1 # seeds: 0 .. 2^64-1
k s64 index @ 0 short
k i+ shift @ 2 short
HEAD=--l1
k f+ range @ 1
k f+ eps @ 0.01 short
for c in mse relmse rell1 psnr ssim errormap; do # one value each of the two, in turn
  HEAD=--$c
  case $c in
  mse | rell1 | ssim) rv=" 1" ev=$(printf %a 0.01) ;;
  *) rv=$(printf %a 1) ev=" 0.01" ;;
  esac
  kl range "$rv"
  kl eps "$ev"
done
HEAD=--mosaic
k i+ n @ 2 short
k i+ fontsize @ 16 short
HEAD=--patches:count=2
k i+ size @ 16 short
HEAD=--patches:size=16
k i+ count @ 2 short
k i+ stride @ 16 short
HEAD=$P
k s64 seed @ 1 short
for m in cull tol abs; do k f+ $m @ 0.5 short; done
KPRE=("$NOISY")
HEAD=--colormap
k f+ max @ 1 short # (max= empty: the 99th percentile, as without it)
HEAD=$D
k i+ tile @ 16 short
k i+ ensemble @ 2 short
kl exposure "" " 0.5" "0.5 " "$(printf %a 0.5)" nan inf -1 # auto|off|E > 0
kl firefly "" " 4" "4x" "$(printf %a 4)" nan inf              # off|R >= 1
HEAD=--kernels:model=$MODEL
kl tile " 16"
kl exposure "$(printf %a 0.5)"
kl firefly ""
HEAD=--rotate
k f deg @ 90 short
HEAD=--shift
k i dx @ 1
k i dy @ 1 short
KPRE=()
KPOST=("$SCENE")
HEAD=--render:res=8x8
k i+ spp @ 1 short
HEAD=--render:res=8x8:spp=1
kl seed " 1" 9223372036854775808 99999999999999999999 -1 # 0 .. 2^63-1
k i+ albedo_spp @ 2 short
k i+ footprint @ 2 short
k i max_bounces @ 2 short # (-1: the scene's)
kl max_bounces -2
HEAD=--render:spp=1
k i+ res @x8 8
k i+ res 8x@ 8 short
kl res 8x8x8 8 "8 x8" 4294967304x4294967304
HEAD=--render:res=8x8:spp=1
k i+ crop @,0,4,4 0 short
kl crop "0, 0,4,4" "0,0,+4,4" "0,0,4,4294967300" 0,0,4
# 0|1 switches: exactly "0" or "1"
for s in "--mirror all" "--augment oneof" "--augment mirror_v" "$D bf16" \
  "--render:res=8x8:spp=1 color_only" "--l1 allow_nonfinite" "$P importance"; do
  HEAD=${s% *} KPRE=("$NOISY" "$REF") KPOST=()
  case $HEAD in --render*) KPRE=() KPOST=("$SCENE") ;; esac
  kl "${s##* }" " 1"
  TESTED["kpcntool switch ${s##* }"]=1
done
# --threads N and --ch's constants are arguments, not modifiers (exit 1 or 2)
STRIP=
b_threads() { CMD=("$KT" --threads "$2" "$NOISY" -o o@@.exr); }
NAME="thread count"
row b_threads "1 2" o@@.exr i+ --threads @ 1 short
b_ch() { CMD=("$KT" "$REF" --ch "R,G,B,A=$2" -o o@@.exr); }
NAME=channel
row b_ch "1 2" o@@.exr f --ch @ 1 short
NAME=

# --- coverage: every option of each --help (kpcntool: every modifier) is in a table above or
# takes no number; an option added later fails here until it gets a row.
untested=()
# coverage TOOL "NON-NUMERIC OPTIONS" HELP-COMMAND...
coverage() {
  local tool=$1 skip=" ${2//$'\n'/ } " o
  shift 2
  for o in $("$@" --help 2>&1 | grep -oE -- '--[a-z0-9-]+' | sort -u); do
    [[ $skip == *" $o "* ]] || [ -n "${TESTED[$tool $o]:-}" ] || untested+=("$tool $o")
  done
}
coverage kpcn-render "--checkpoint --color-only --compression --half --quiet --version" "$KR"
coverage "kpcn-dataset plan" "--eval-variants --force --no-preview --scenes --texture-dir" "$KD" plan
coverage "kpcn-dataset run" "--dry-run --list --renderer" "$KD" run
coverage "kpcn-dataset patches" "--allow-partial --dtype --importance --split" "$KD" patches
coverage kpcn-train "--average --best --best-by --bf16 --ckpt --compare --csv --freeze --graft
  --init --linear --loss --loss2 --no-colorswap --no-mirror --no-rotate --no-shift
  --normalize-exposure --plot --preset --quiet --record-exposure --resume --snapshots
  --source-weight --split --staircase --store --title --val --val-from-store --val-store
  --version --x --y" "$KTR"
# kpcntool: switches count once for every command; names and files take no number
flags=" all bf16 allow_nonfinite mirror_v oneof importance color_only "
words=" model method map perm channels display metric labels font dir out branch view config from looks "
while read -r c m; do
  if [[ $flags == *" $m "* ]]; then
    [ -n "${TESTED[kpcntool switch $m]:-}" ] || untested+=("kpcntool $c:$m")
  elif [[ $words != *" $m "* ]] && [ -z "${TESTED[kpcntool $c $m]:-}" ]; then
    untested+=("kpcntool $c:$m")
  fi
done < <("$KT" --help | awk '/^  --?[a-z]/ { c = $1 }
  /modifiers:/ { sub(/.*modifiers: /, ""); n = split($0, a, ", "); for (i = 1; i <= n; i++) print c, a[i] }')
for o in "${untested[@]}"; do
  echo "FAIL: numeric option not in any table: $o"
done

wait
ok=0 fails=${#untested[@]}
for i in $(seq 1 $n); do
  if grep -q '^ok' "r$i"; then
    ok=$((ok + 1))
  else
    cat "r$i"
    fails=$((fails + 1))
  fi
done
echo "cli_option_values: $ok checks passed, $fails failed"
[ "$fails" -eq 0 ]
