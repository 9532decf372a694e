#!/bin/sh
# kpcn-train --record-exposure: a copy of a model recording the median exposure of a patch
# store's training images; same weights; bad inputs named, no output file. --set-eps: the
# same weights with another demodulation epsilon; set back, the original function bit for bit.
# --graft: one branch from another model, mismatches named. --freeze: usage and provenance.
# --firefly: bad ratios named. --time-limit: exit 0, model and checkpoint, bit-exact resume.
# A periodic checkpoint that cannot be written (full disk, file-size limit): exit 1, named,
# nothing half-written. --resume refuses another --source-lr-scale or store and malformed
# checkpoint metadata, and keeps the best model's record without a CSV; a run stopped on a
# CSV row writes no rate in its last row.
# usage: test_train_cli.sh KPCN_TRAIN KPCNTOOL TESTDATA
set -u
K=$1; T=$2; TD=$3
D=$(mktemp -d /tmp/kpcn_trcli_XXXXXX)
trap 'rm -rf "$D"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
N="$TD/dataset/sample_noisy.exr"; M="$TD/models/kpcn-cpu.safetensors"
"$T" "$N" "$TD/dataset/sample_ref.exr" --patches:size=16:count=6:cull=1:out="$D/p.kps" || fail "patches"
"$K" --record-exposure "$D/m.safetensors" "$M" "$D/p.kps" >"$D/log" || fail "record-exposure"
E=$(sed -n 's/.*recording exposure \([0-9.e+-]*\)$/\1/p' "$D/log")
[ -n "$E" ] || fail "no exposure printed: $(cat "$D/log")"
grep -aq '\\"exposure\\":' "$D/m.safetensors" || fail "model header records no exposure"
# the store's one source is this image, so the exposure recorded is its own; the weights are
# the model's: by default the new model gives the original's result at that exposure, bit
# for bit
"$T" "$N" --exposure --json >"$D/e.json" || fail "--exposure"
EI=$(sed -n 's/.*"exposure": *\([0-9.eE+-]*\).*/\1/p' "$D/e.json")
[ -n "$EI" ] || fail "no exposure in $(cat "$D/e.json")"
awk -v a="$E" -v b="$EI" 'BEGIN { d = a - b; if (d < 0) d = -d; exit !(b > 0 && d <= 1e-6 * b) }' ||
  fail "recorded exposure $E is not the image's own $EI"
"$T" "$N" --denoise:model="$D/m.safetensors" -o "$D/a.exr" || fail "denoise with the new model"
"$T" "$N" --denoise:model="$M":exposure="$E" -o "$D/b.exr" || fail "denoise at exposure $E"
"$T" --json "$D/a.exr" "$D/b.exr" --l1 >"$D/l1.json" || fail "l1"
grep -Eq '"l1": *0(\.0*)?([,} ]|$)' "$D/l1.json" || fail "new model differs: $(cat "$D/l1.json")"
# bad inputs: a missing store, a store that is no store, a model that is no model
for args in "$M $D/nope.kps" "$M $N" "$N $D/p.kps"; do
  # shellcheck disable=SC2086
  if "$K" --record-exposure "$D/bad.safetensors" $args 2>"$D/err"; then fail "accepted: $args"; fi
  # the message names the file at fault (the last argument for a bad store, else the model)
  case "$args" in "$M $D/nope.kps") want="$D/nope.kps" ;; "$M $N") want="$N" ;; *) want="$N" ;; esac
  grep -qF -- "$want" "$D/err" || fail "error does not name '$want': $(cat "$D/err")"
  [ ! -e "$D/bad.safetensors" ] || fail "partial output written: $args"
done
"$K" --record-exposure "$D/bad.safetensors" "$M" 2>"$D/err" && fail "accepted without a store"
grep -q 'expected' "$D/err" || fail "usage error unclear: $(cat "$D/err")"
# --set-eps: the model's eps changes the denoised result; set back to the original's (as its
# header writes it, e.g. 0.00316000008), the result equals the original model's bit for bit
ME=$(grep -ao '"kpcn.eps":"[^"]*"' "$M" | head -1 | sed 's/.*:"\([^"]*\)"/\1/')
[ -n "$ME" ] || fail "no kpcn.eps in the shipped model's header"
"$K" --set-eps "$D/e4.safetensors" "$M" 1e-4 >"$D/log" || fail "set-eps"
grep -aq '"kpcn.eps":"9.99999975e-05"' "$D/e4.safetensors" || fail "model header lacks eps 1e-4"
"$K" --set-eps "$D/back.safetensors" "$D/e4.safetensors" "$ME" >"$D/log" || fail "set-eps back"
"$T" "$N" --denoise:model="$D/e4.safetensors" -o "$D/e4.exr" || fail "denoise eps 1e-4"
"$T" "$N" --denoise:model="$D/back.safetensors" -o "$D/back.exr" || fail "denoise eps back"
"$T" "$N" --denoise:model="$M" -o "$D/orig.exr" || fail "denoise original"
"$T" --json "$D/back.exr" "$D/orig.exr" --l1 >"$D/l1.json" || fail "l1 back"
grep -Eq '"l1": *0(\.0*)?([,} ]|$)' "$D/l1.json" || fail "eps set back differs: $(cat "$D/l1.json")"
"$T" --json "$D/e4.exr" "$D/orig.exr" --l1 >"$D/l1.json" || fail "l1 e4"
grep -Eq '"l1": *0(\.0*)?([,} ]|$)' "$D/l1.json" && fail "eps 1e-4 changed nothing"
# --eps trains a new model with it, and sets it on an --init model
"$K" --store "$D/p.kps" -o "$D/t.safetensors" --preset tiny --iters 1 --batch 2 --patch 16 \
  --eps 1e-4 --csv '' --plot '' --ckpt '' --quiet || fail "train --eps"
grep -aq '"kpcn.eps":"9.99999975e-05"' "$D/t.safetensors" || fail "trained model lacks eps 1e-4"
"$K" --store "$D/p.kps" -o "$D/i.safetensors" --init "$D/t.safetensors" --iters 1 --batch 2 \
  --patch 16 --eps 2e-4 --csv '' --plot '' --ckpt '' --quiet || fail "train --init --eps"
grep -aq '"kpcn.eps":"0.000199999995"' "$D/i.safetensors" || fail "--init model lacks eps 2e-4"
for bad in 0 1 0.6 1e-10 -1e-3 abc 1e-3x; do
  "$K" --set-eps "$D/bad.safetensors" "$M" "$bad" 2>"$D/err"
  rc=$?
  [ $rc -eq 2 ] || fail "--set-eps $bad: exit $rc (want 2)"
  grep -qF "not a number in [1e-9, 0.5]" "$D/err" || fail "--set-eps $bad unclear: $(cat "$D/err")"
  [ ! -e "$D/bad.safetensors" ] || fail "output written for --set-eps $bad"
done
"$K" --set-eps "$D/bad.safetensors" "$N" 1e-4 2>"$D/err" && fail "--set-eps of a non-model accepted"
grep -qF -- "$N" "$D/err" || fail "--set-eps error does not name the model: $(cat "$D/err")"
[ ! -e "$D/bad.safetensors" ] || fail "output written for a non-model"
"$K" --set-eps "$D/bad.safetensors" "$M" 2>"$D/err" && fail "--set-eps without EPS accepted"
grep -q 'expected' "$D/err" || fail "--set-eps usage error unclear: $(cat "$D/err")"
# --graft: a specular branch may come from a model of another eps (here the same weights, so
# the result is the eps-1e-4 model's bit for bit); a diffuse one may not, nor a branch of
# another architecture or exposure; bad usage is exit 2; never an output file on error
"$K" --graft "$D/g.safetensors" "$D/e4.safetensors" specular "$M" >"$D/log" || fail "graft"
grep -q "specular branch from" "$D/log" || fail "graft message: $(cat "$D/log")"
grep -aq '"train.grafted":"specular branch from' "$D/g.safetensors" || fail "no train.grafted"
grep -aq '"kpcn.eps":"9.99999975e-05"' "$D/g.safetensors" || fail "grafted model lost its eps"
"$T" "$N" --denoise:model="$D/g.safetensors" -o "$D/g.exr" || fail "denoise grafted"
"$T" --json "$D/g.exr" "$D/e4.exr" --l1 >"$D/l1.json" || fail "l1 graft"
grep -Eq '"l1": *0(\.0*)?([,} ]|$)' "$D/l1.json" || fail "graft changed: $(cat "$D/l1.json")"
for case in "diffuse $M:eps" "specular $D/t.safetensors:architecture" "specular $D/m.safetensors:exposure"; do
  spec=${case%:*}; want=${case##*:}
  # shellcheck disable=SC2086
  "$K" --graft "$D/bad.safetensors" "$D/e4.safetensors" $spec 2>"$D/err"
  rc=$?
  [ $rc -eq 1 ] || fail "--graft $spec: exit $rc (want 1)"
  grep -q "$want" "$D/err" || fail "--graft $spec does not say '$want': $(cat "$D/err")"
  [ ! -e "$D/bad.safetensors" ] || fail "output written for --graft $spec"
done
for args in "$M spec $M" "$M specular"; do
  # shellcheck disable=SC2086
  "$K" --graft "$D/bad.safetensors" $args 2>"$D/err"
  rc=$?
  [ $rc -eq 2 ] || fail "--graft $args: exit $rc (want 2)"
  [ ! -e "$D/bad.safetensors" ] || fail "output written for --graft $args"
done
# --firefly: a ratio below 1 or no number is refused naming the option, nothing is written
for bad in 0.5 abc; do
  if "$K" --store "$D/p.kps" -o "$D/f.safetensors" --iters 1 --firefly $bad 2>"$D/err"; then
    fail "--firefly $bad accepted"
  fi
  grep -q firefly "$D/err" || fail "--firefly error unclear: $(cat "$D/err")"
  [ ! -e "$D/f.safetensors" ] || fail "output written for --firefly $bad"
done
# usage mistakes are refused before anything is read or written (exit 2), naming the option
# (--dilations with too many values or junk, --ssim-window without an SSIM loss or even,
# shape options an --init model does not have)
bad_usage() {
  pat=$1; shift
  "$K" --store "$D/p.kps" -o "$D/u.safetensors" --iters 1 "$@" 2>"$D/err"
  rc=$?
  [ $rc -eq 2 ] || fail "exit $rc (want 2) for: $* ($(cat "$D/err"))"
  grep -qF -- "$pat" "$D/err" || fail "message lacks '$pat' for: $*: $(cat "$D/err")"
  [ ! -e "$D/u.safetensors" ] && [ ! -e "$D/u.safetensors.csv" ] || fail "output written for: $*"
}
bad_usage "at most 3 positive integers" --preset tiny --dilations 1,2,3,4
bad_usage "at most 3 positive integers" --preset tiny --dilations 1,2,1x
bad_usage "item 3 is not an integer in [1, 64]" --preset tiny --dilations 1,2,x
bad_usage "item 1 is not an integer in [1, 64]" --preset tiny --dilations 65
bad_usage "--ssim-window has no effect" --ssim-window 7
bad_usage "the window must be odd" --loss2 ssim --ssim-window 4
bad_usage "--layers asks for 5 hidden layers, the --init model" --init "$M" --layers 5
bad_usage "--preset asks for" --init "$M" --preset tiny
bad_usage "--average must be the first argument" --average "$M"
bad_usage "--set-eps must be the first argument" --set-eps "$M"
bad_usage "--eps" --eps 0
bad_usage "--freeze: 'both' is not diffuse or specular" --init "$M" --freeze both
bad_usage "--freeze given for both branches" --init "$M" --freeze diffuse --freeze specular
# --freeze: needs a model to start from (a usage mistake: exit 2, nothing written); with one,
# the model says which branch it kept (test_train_pipeline checks the weights bit for bit)
bad_usage "needs a model to start from" --freeze specular
# architectures the trainer cannot build and --widen without a model: usage mistakes too
# (they were exit 1, after the store was read, naming the library's field only)
bad_usage "kernel_size = 4: must be odd" --preset tiny --kernel 4
bad_usage "conv_size[0] = 2: must be odd" --preset tiny --conv 2
bad_usage "(widen_channels, kpcn-train --widen) needs an init model" --preset tiny --widen 16
# options that conflict or would do nothing (session 63; they were accepted, or read the store
# first and exited 1 on something else): --channels other than --widen's, --source-lr-scale
# without a source weight, --val-every without validation images, --best-by without --best
bad_usage "--channels 32 conflicts with --widen 64" --init "$M" --widen 64 --channels 32
bad_usage "--source-lr-scale has no effect without --source-weight" --preset tiny --source-lr-scale 2
bad_usage "--val-every has no effect without --val or --val-store" --preset tiny --val-every 5
bad_usage "--best-by has no effect without --best" --preset tiny --best-by geomean
# an --init model without a source weight: known once it is read (exit 1), nothing written
"$K" --store "$D/p.kps" -o "$D/u.safetensors" --init "$D/t.safetensors" --iters 1 --batch 2 \
  --patch 16 --source-lr-scale 2 --csv '' --plot '' --ckpt '' 2>"$D/err"
rc=$?
[ $rc -eq 1 ] || fail "--init without a source weight, --source-lr-scale 2: exit $rc (want 1): $(cat "$D/err")"
grep -qF "source_lr_scale (--source-lr-scale) has no effect: model '$D/t.safetensors' predicts no source weight" "$D/err" ||
  fail "--source-lr-scale on an --init model without a source weight unclear: $(cat "$D/err")"
[ ! -e "$D/u.safetensors" ] || fail "output written for --source-lr-scale without a source weight"
# an output that cannot be written is a usage mistake too (exit 2, as in the other tools)
bad_usage "folder '$D/nodir'" --plot "$D/nodir/u.png"
bad_usage "must end in .png" --plot "$D/u.jpg"
# --compare alone says what it takes, not that it must come first
"$K" --compare 2>"$D/err"
rc=$?
[ $rc -eq 2 ] && grep -q "expected OUT.png LABEL=RUN.csv" "$D/err" || fail "--compare alone: rc $rc: $(cat "$D/err")"
"$K" --store "$D/p.kps" -o "$D/z.safetensors" --init "$D/t.safetensors" --iters 1 --batch 2 \
  --patch 16 --freeze specular --csv '' --plot '' --ckpt '' --quiet || fail "train --freeze"
grep -aq '"train.frozen":"specular"' "$D/z.safetensors" || fail "model lacks train.frozen"
# an output that would overwrite the patch store is refused; the store is intact
"$K" --store "$D/p.kps" -o "$D/c.safetensors" --iters 1 --csv "$D/p.kps" 2>"$D/err"
rc=$?
[ $rc -eq 2 ] || fail "--csv over the store: exit $rc (want 2)"
grep -q "are the same file" "$D/err" || fail "store clash unclear: $(cat "$D/err")"
"$T" "$N" "$TD/dataset/sample_ref.exr" --patches:size=16:count=6:cull=1:out="$D/p2.kps" || fail "patches 2"
cmp -s "$D/p.kps" "$D/p2.kps" || fail "the store was changed"
# every mode that writes a file refuses an output that is one of its inputs, before any work
if "$K" --record-exposure "$D/p.kps" "$M" "$D/p.kps" 2>"$D/err"; then fail "record-exposure over the store"; fi
grep -q "is the same file as input" "$D/err" || fail "record-exposure clash unclear: $(cat "$D/err")"
cmp -s "$D/p.kps" "$D/p2.kps" || fail "record-exposure changed the store"
if "$K" --set-eps "$D/m.safetensors" "$D/m.safetensors" 0.01 2>"$D/err"; then fail "set-eps in place"; fi
grep -q "is the same file as input" "$D/err" || fail "set-eps clash unclear: $(cat "$D/err")"
if "$K" --compare "$D/cmp.exr" a="$D/c.csv" 2>"$D/err"; then fail "--compare to .exr accepted"; fi
grep -q "must end in .png" "$D/err" || fail "--compare extension unclear: $(cat "$D/err")"
# outputs that cannot be written are refused before training, not after it: nothing is left
for o in "-o $D/nodir/x.safetensors" "-o $D/y.safetensors --plot $D/nodir/y.png" \
  "-o $D/y.safetensors --ckpt $D/nodir/y.ckpt" "-o $D/y.safetensors --csv $D" "-o ''"; do
  # shellcheck disable=SC2086
  eval "\"$K\" --store \"$D/p.kps\" --preset tiny --iters 50 --batch 2 --patch 16 $o" 2>"$D/err"
  rc=$?
  [ $rc -eq 2 ] || fail "exit $rc (want 2) for: $o"
  grep -Eq "folder '$D/nodir'|is a directory|empty file name" "$D/err" || fail "unclear for $o: $(cat "$D/err")"
  [ -z "$(ls "$D" | grep -E '^y\.|^x\.')" ] || fail "files left for $o: $(ls "$D")"
done
# the validation inputs' own figures come first (what a model must beat), equal to kpcntool's;
# a model worse than them gets a warning at the end: validated here on the reference itself
# (noisy relMSE 0), which no model can beat
R="$TD/dataset/sample_ref.exr"
"$K" --store "$D/p.kps" -o "$D/vv.safetensors" --preset tiny --iters 2 --batch 2 --patch 16 \
  --csv '' --plot '' --ckpt '' --val "$N,$R" --val "$R,$R" 2>"$D/log" || fail "train with --val"
noisy=$(sed -n 's/.*validation inputs as rendered (noisy): relMSE \([^ ]*\) .*/\1/p' "$D/log")
"$T" --json "$N" "$R" --relmse >"$D/nr.json" || fail "noisy relmse"
want=$(/usr/bin/python3 -c 'import json,sys; print("%.4g" % (json.load(open(sys.argv[1]))["relmse"] / 2))' "$D/nr.json")
[ -n "$noisy" ] && [ "$noisy" = "$want" ] || fail "noisy validation figure '$noisy', want '$want' (half of kpcntool's: the second pair is 0)"
grep -q "the model is worse than its noisy inputs" "$D/log" || fail "no worse-than-noisy warning: $(cat "$D/log")"
# a fine-tune's starting point: the --init model as given (its own exposure, as kpcntool runs
# it), equal to kpcntool's figure, and at the store's exposure when that differs (what the
# fine-tuned model records; session 59: a run's figures looked unlike its --init model's)
"$K" --store "$D/p.kps" -o "$D/ft.safetensors" --init "$M" --stage1-iters 0 --iters 1 --lr 1e-12 \
  --batch 2 --patch 16 --csv '' --plot '' --ckpt '' --val "$N,$R" 2>"$D/log" || fail "fine-tune with --val: $(cat "$D/log")"
"$T" --json "$N" --denoise:model="$M" "$R" --relmse >"$D/ir.json" || fail "init relmse"
want=$(/usr/bin/python3 -c 'import json,sys; print("%.4g" % json.load(open(sys.argv[1]))["relmse"])' "$D/ir.json")
grep -q "the --init model as given (exposure [0-9.e+-]*): relMSE $want " "$D/log" ||
  fail "--init figure is not kpcntool's $want: $(cat "$D/log")"
grep -q "the --init model at the store's exposure" "$D/log" || fail "no store-exposure figure: $(cat "$D/log")"
# --val-store: the full renders of another store's sources (vs.kps is cut from the sample pair,
# so its one source gives the same noisy figure); the training store itself is refused,
# and --val-from-store (a train store's own 'val' sources) says what replaced it
"$T" "$N" "$R" --patches:size=16:count=6:cull=1:out="$D/vs.kps" || fail "patches for --val-store"
"$K" --store "$D/p.kps" -o "$D/vv.safetensors" --preset tiny --iters 2 --batch 2 --patch 16 \
  --csv '' --plot '' --ckpt '' --val-store "$D/vs.kps" 2>"$D/log" || fail "--val-store: $(cat "$D/log")"
grep -q "validation inputs as rendered (noisy): relMSE $(printf '%.4g' "$(/usr/bin/python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["relmse"])' "$D/nr.json")") " "$D/log" ||
  fail "--val-store did not validate on the sample pair: $(cat "$D/log")"
bad_usage "is the training store" --val-store "$D/p.kps"
bad_usage "--val-from-store is replaced by --val-store" --val-from-store
# an output that is one of --val-store's images is a usage mistake as with --val (exit 2, it
# was 1: the store's pairs were listed after the usage check), and the image is left alone
# (copies: a regression must not write over testdata)
mkdir "$D/vsrc"
cp "$N" "$D/vsrc/n.exr" && cp "$R" "$D/vsrc/r.exr" || fail "copy validation images"
"$T" "$D/vsrc/n.exr" "$D/vsrc/r.exr" --patches:size=16:count=6:cull=1:out="$D/vsrc/v.kps" >/dev/null ||
  fail "patches for --val-store copies"
for img in n r; do
  "$K" --store "$D/p.kps" -o "$D/y.safetensors" --preset tiny --iters 2 --batch 2 --patch 16 \
    --plot '' --val-store "$D/vsrc/v.kps" --csv "$D/vsrc/$img.exr" 2>"$D/err"
  rc=$?
  [ $rc -eq 2 ] || fail "--csv over --val-store's $img.exr: exit $rc (want 2): $(cat "$D/err")"
  grep -qF "the CSV log (--csv) '$D/vsrc/$img.exr' is the same file as a --val" "$D/err" ||
    fail "--csv over --val-store's $img.exr unclear: $(cat "$D/err")"
  [ -z "$(ls "$D" | grep -E '^y\.')" ] || fail "files left for --csv over --val-store's $img.exr: $(ls "$D")"
done
cmp -s "$N" "$D/vsrc/n.exr" && cmp -s "$R" "$D/vsrc/r.exr" || fail "a --val-store image was changed"
# a training patch larger than the store's says which two options meet
"$K" --store "$D/p.kps" -o "$D/vv.safetensors" --preset tiny --iters 1 --patch 32 2>"$D/err"
rc=$?
[ $rc -eq 1 ] && grep -q "train with --patch 16 or less, or cut the store with kpcn-dataset patches --size 33" "$D/err" ||
  fail "--patch above the store's size: rc $rc: $(cat "$D/err")"
# a plot under another extension, a plot without its CSV log, snapshots into a file, a NaN in
# a validation input: refused before training
for o in "--plot $D/p.exr:must end in .png" "--plot $D/p.png --csv '':which --csv '' turns off" \
  "--snapshots $D/p.kps:exists and is not a directory"; do
  if eval "\"$K\" --store \"$D/p.kps\" -o \"$D/y.safetensors\" --preset tiny --iters 50 --batch 2 --patch 16 ${o%%:*}" 2>"$D/err"; then
    fail "accepted: ${o%%:*}"
  fi
  grep -qF -- "${o#*:}" "$D/err" || fail "unclear for ${o%%:*}: $(cat "$D/err")"
  [ -z "$(ls "$D" | grep -E '^y\.')" ] || fail "files left for ${o%%:*}: $(ls "$D")"
done
oiiotool --pattern constant:color=0.5,nan,0.5 1x1 3 "$N" --paste +3+1 -o "$D/vnoisy.exr" || fail "NaN input"
if "$K" --store "$D/p.kps" -o "$D/v.safetensors" --preset tiny --iters 50 --batch 2 --patch 16 \
  --val "$D/vnoisy.exr,$TD/dataset/sample_ref.exr" 2>"$D/err"; then fail "NaN validation input accepted"; fi
grep -q "validation input '$D/vnoisy.exr': 1 non-finite value" "$D/err" || fail "NaN input unclear: $(cat "$D/err")"
[ ! -e "$D/v.safetensors" ] || fail "a model written with a NaN validation input"
# a validation reference with a NaN is refused, naming the file and the pixel
oiiotool --pattern constant:color=0.5,nan,0.5 1x1 3 "$TD/dataset/sample_ref.exr" --ch R,G,B \
  --paste +5+2 -o "$D/vref.exr" || fail "NaN reference"
if "$K" --store "$D/p.kps" -o "$D/v.safetensors" --preset tiny --iters 1 --batch 2 --patch 16 \
  --val "$N,$D/vref.exr" 2>"$D/err"; then fail "NaN validation reference accepted"; fi
grep -q "vref.exr': non-finite colour at pixel (5, 2)" "$D/err" || fail "NaN reference unclear: $(cat "$D/err")"
# a validation input without a buffer the KPCN reads is refused before training, not after
# it (the whole run was lost, and its CSV left alone)
"$T" "$N" --ch R,G,B,Z,N.X,N.Y,N.Z,N.var,Z.var,albedo.R,albedo.G,albedo.B,albedo.var,color.var,diffuse.R,diffuse.G,diffuse.B,diffuse.var,specular.R,specular.G,specular.B,specular.var \
  -o "$D/novis.exr" || fail "input without visibility"
if "$K" --store "$D/p.kps" -o "$D/v.safetensors" --preset tiny --iters 50 --batch 2 --patch 16 \
  --val "$D/novis.exr,$R" 2>"$D/err"; then fail "validation input without visibility accepted"; fi
grep -q "validation input '$D/novis.exr': .*missing buffer 'visibility'" "$D/err" ||
  fail "missing buffer unclear: $(cat "$D/err")"
[ -z "$(ls "$D" | grep -E '^v\.')" ] || fail "files left for a validation input without visibility: $(ls "$D")"
# --iters may grow on a resume when the stage-1 length is left to its default (0.6 * iters:
# the checkpoint's 2 is kept, not 0.6 * 8); the start-up line names the architecture in use
"$K" --store "$D/p.kps" -o "$D/g.safetensors" --preset tiny --iters 4 --batch 2 --patch 16 \
  --plot '' 2>"$D/log" || fail "4 iterations: $(cat "$D/log")"
"$K" --store "$D/p.kps" -o "$D/g.safetensors" --preset tiny --iters 8 --batch 2 --patch 16 \
  --plot '' --resume 2>"$D/log" || fail "--iters grown on resume: $(cat "$D/log")"
grep -q "tiny architecture, 8 iterations (stage 1: 2)" "$D/log" || fail "start-up line: $(cat "$D/log")"
grep -q "finished at iteration 8" "$D/log" || fail "not resumed to 8: $(cat "$D/log")"
"$K" --store "$D/p.kps" -o "$D/g.safetensors" --preset tiny --iters 10 --stage1-iters 3 \
  --batch 2 --patch 16 --plot '' --resume 2>"$D/err" && fail "resume with another --stage1-iters"
grep -q "train.stage1_iters = 2, this run uses 3 (--stage1-iters)" "$D/err" ||
  fail "stage-1 mismatch unclear: $(cat "$D/err")"
"$K" --store "$D/p.kps" -o "$D/gi.safetensors" --init "$D/g.safetensors" --iters 1 --batch 2 \
  --patch 16 --csv '' --plot '' --ckpt '' 2>"$D/log" || fail "--init tiny: $(cat "$D/log")"
grep -q "kpcn-train: tiny architecture (from --init)" "$D/log" || fail "--init start-up line: $(cat "$D/log")"
# --compare: a column a run has no value in (no --val), or values a log axis cannot show,
# is refused naming the run (it drew an empty plot, or a legend entry without a line)
if "$K" --compare "$D/ce.png" --y val_relmse a="$D/g.safetensors.csv" 2>"$D/err"; then
  fail "--compare of an empty column accepted"
fi
grep -q "run 'a' .* has no value in column 'val_relmse' (was it trained without --val?)" "$D/err" ||
  fail "--compare empty column unclear: $(cat "$D/err")"
[ ! -e "$D/ce.png" ] || fail "--compare wrote a plot of nothing"
printf 'iter,loss,elapsed_s\n1,0.5,1\n2,-0.25,2\n' >"$D/neg.csv"
if "$K" --compare "$D/ce.png" b="$D/neg.csv" 2>"$D/err"; then fail "--compare of a negative value on a log axis"; fi
grep -q "1 value(s) of 'loss' are <= 0, which a log axis cannot show (plot with --linear)" "$D/err" ||
  fail "--compare negative unclear: $(cat "$D/err")"
"$K" --compare "$D/ce.png" --linear b="$D/neg.csv" 2>"$D/err" || fail "--compare --linear: $(cat "$D/err")"
# stopped by a signal: the checkpoint and the model so far are written, and the exit status
# (128 + the signal) says it did not finish
"$K" --store "$D/p.kps" -o "$D/s.safetensors" --preset tiny --iters 1000000 --batch 2 --patch 16 \
  --plot '' 2>"$D/err" &
pid=$!
i=0 # the start-up line is printed when the run starts, after the signal handlers are set
while ! grep -q "GFLOP/iteration" "$D/err" 2>/dev/null && [ $i -lt 1200 ]; do
  sleep 0.1
  i=$((i + 1))
done
sleep 0.5
kill -TERM $pid
wait $pid
rc=$?
[ $rc -eq 143 ] || fail "SIGTERM: exit $rc, not 143: $(cat "$D/err")"
[ -e "$D/s.safetensors" ] && [ -e "$D/s.safetensors.ckpt" ] || fail "SIGTERM: no model or checkpoint: $(ls "$D")"
# --- checkpoint helpers for the sections below. st_cmp same A B: two safetensors files (models
# or checkpoints) are equal bit for bit but for the wall-clock metadata (train.seconds,
# train.elapsed_s: docs/training.md, "Determinism"); st_cmp weights MODEL CKPT: every tensor
# of the model is in the checkpoint with the same bytes; st_cmp meta FILE KEY prints a
# metadata value
st_cmp() {
  /usr/bin/python3 - "$@" <<'PYEOF'
import json, struct, sys
def load(p):
    b = open(p, "rb").read()
    n = struct.unpack("<Q", b[:8])[0]
    return json.loads(b[8:8 + n]), b[8 + n:]
mode, a = sys.argv[1], sys.argv[2]
ha, da = load(a)
if mode == "meta":
    print(ha.get("__metadata__", {}).get(sys.argv[3], ""))
    sys.exit(0)
hb, db = load(sys.argv[3])
if mode == "same":
    wall = ("train.seconds", "train.elapsed_s")
    ma = {k: v for k, v in ha.pop("__metadata__", {}).items() if k not in wall}
    mb = {k: v for k, v in hb.pop("__metadata__", {}).items() if k not in wall}
    for k in sorted(set(ma) | set(mb)):
        if ma.get(k) != mb.get(k):
            sys.exit("metadata %s: %r against %r" % (k, ma.get(k), mb.get(k)))
    if ha != hb:
        sys.exit("tensor lists differ")
    if da != db:
        bad = [k for k, e in ha.items()
               if da[e["data_offsets"][0]:e["data_offsets"][1]] != db[e["data_offsets"][0]:e["data_offsets"][1]]]
        sys.exit("tensor data differ: %s" % ", ".join(bad[:5]))
elif mode == "weights":
    for k, e in ha.items():
        if k == "__metadata__":
            continue
        if k not in hb:
            sys.exit("tensor %s is not in %s" % (k, sys.argv[3]))
        (a0, a1), (b0, b1) = e["data_offsets"], hb[k]["data_offsets"]
        if da[a0:a1] != db[b0:b1]:
            sys.exit("tensor %s differs from the checkpoint's" % k)
PYEOF
}
# tiny runs on the store above; the same thread count everywhere (determinism holds for one)
tr_run() { "$K" --store "$D/p.kps" --preset tiny --batch 2 --patch 16 --plot '' --threads 2 "$@"; }
# --time-limit MINUTES (checked before each iteration): a run it stops exits 0 (the run's plan,
# not a failure) and writes the checkpoint and the model so far (a valid model: it denoises,
# and its weights are the checkpoint's); --resume continues from there, and the result equals
# the uninterrupted run of the same --iters bit for bit: model, checkpoint, and the CSV's
# iter/stage/lr/loss columns. The limit is 0.002 minutes (0.12 s): where it stops varies
# with the machine, so only 0 < stop < iters is asked, and the iteration 2000 it runs to
# lies past it on any machine (this one does 2000 iterations in about 1 s)
tr_run --iters 2000 -o "$D/tl.safetensors" --time-limit 0.002 2>"$D/log"
rc=$?
[ $rc -eq 0 ] || fail "--time-limit stop: exit $rc, not 0: $(cat "$D/log")"
stop=$(sed -n 's/.*time limit reached at iteration \([0-9]*\): checkpointing$/\1/p' "$D/log")
[ -n "$stop" ] && [ "$stop" -gt 0 ] && [ "$stop" -lt 2000 ] ||
  fail "--time-limit 0.002 did not stop the run between iterations 1 and 1999: $(cat "$D/log")"
grep -qF "stopped at iteration $stop; model '$D/tl.safetensors' (resume with --resume)" "$D/log" ||
  fail "--time-limit stop line: $(cat "$D/log")"
[ -e "$D/tl.safetensors" ] && [ -e "$D/tl.safetensors.ckpt" ] ||
  fail "--time-limit: no model or checkpoint: $(ls "$D")"
[ "$(st_cmp meta "$D/tl.safetensors.ckpt" train.iteration)" = "$stop" ] ||
  fail "--time-limit: checkpoint at iteration $(st_cmp meta "$D/tl.safetensors.ckpt" train.iteration), stopped at $stop"
[ "$(st_cmp meta "$D/tl.safetensors" train.iterations)" = "$stop" ] ||
  fail "--time-limit: model records $(st_cmp meta "$D/tl.safetensors" train.iterations) iterations, stopped at $stop"
# not before the limit: 0.002 minutes are 0.12 s of training time
el=$(st_cmp meta "$D/tl.safetensors.ckpt" train.elapsed_s)
awk -v e="$el" 'BEGIN { exit !(e >= 0.12) }' || fail "--time-limit 0.002 (minutes) stopped after $el s"
st_cmp weights "$D/tl.safetensors" "$D/tl.safetensors.ckpt" || fail "--time-limit: the model is not the checkpoint's"
"$T" "$N" --denoise:model="$D/tl.safetensors" -o "$D/tl.exr" || fail "the --time-limit model does not denoise"
# the same options with --resume (a time limit it does not reach) end where the uninterrupted
# run ends
tr_run --iters 2000 -o "$D/tl.safetensors" --time-limit 10 --resume 2>"$D/log" ||
  fail "--resume after --time-limit: $(cat "$D/log")"
grep -qF "finished at iteration 2000; model '$D/tl.safetensors'" "$D/log" || fail "resume did not finish: $(cat "$D/log")"
tr_run --iters 2000 -o "$D/tu.safetensors" 2>"$D/log" || fail "2000 iterations: $(cat "$D/log")"
st_cmp same "$D/tu.safetensors" "$D/tl.safetensors" ||
  fail "stopped by --time-limit at $stop and resumed: the model differs from the uninterrupted run's"
st_cmp same "$D/tu.safetensors.ckpt" "$D/tl.safetensors.ckpt" ||
  fail "stopped by --time-limit at $stop and resumed: the checkpoint differs from the uninterrupted run's"
cut -d, -f1-4 "$D/tu.safetensors.csv" >"$D/tu.cols"
cut -d, -f1-4 "$D/tl.safetensors.csv" >"$D/tl.cols"
cmp -s "$D/tu.cols" "$D/tl.cols" ||
  fail "stopped by --time-limit at $stop and resumed: the CSV differs: $(diff "$D/tu.cols" "$D/tl.cols" | head -5)"
# a periodic checkpoint that cannot be written fails the run (exit 1), naming the file and the
# reason; the file it would replace is kept whole (written to a temporary name, renamed only
# once complete) and no temporary is left; no model is written.
# (1) the disk fills up at the second periodic save (a tmpfs with room for one checkpoint,
# not two: the old one stays until the new one is complete): the first is kept, and --resume
# from it ends at the uninterrupted run's state bit for bit. Needs a mount namespace (root,
# CAP_SYS_ADMIN): skipped, saying so, where that is refused
C=$(wc -c <"$D/tu.safetensors.ckpt")
SZ=$(((C + 4095) / 4096 * 6)) # kB: 1.5 checkpoints (rounded up to pages: 6 kB per 4 kB page)
mkdir "$D/tf"
# shellcheck disable=SC2016
if ! unshare -m sh -c 'mount -t tmpfs -o size=4k tmpfs "$1"' sh "$D/tf" 2>"$D/err"; then
  echo "SKIP: full-disk checkpoint check: cannot mount a tmpfs in a mount namespace: $(cat "$D/err")"
else
  # shellcheck disable=SC2016 # the script's own positional parameters
  unshare -m sh -c 'mount -t tmpfs -o size="$1"k tmpfs "$2" || exit 1
    d=$3
    shift 3
    "$@" 2>"$d/err"
    echo $? >"$d/frc"
    ls -A "$d/tf" >"$d/fleft"
    [ ! -e "$d/tf/x.ckpt" ] || cp "$d/tf/x.ckpt" "$d/fb.ckpt"' sh "$SZ" "$D/tf" "$D" \
    "$K" --store "$D/p.kps" --preset tiny --batch 2 --patch 16 --plot '' --threads 2 \
    --iters 20 --ckpt-every 5 -o "$D/fb.safetensors" --ckpt "$D/tf/x.ckpt" ||
    fail "full-disk run: tmpfs of ${SZ}k: $(cat "$D/err")"
  rc=$(cat "$D/frc")
  [ "$rc" = 1 ] || fail "checkpoint on a full disk: exit $rc, not 1: $(cat "$D/err")"
  grep -F "'$D/tf/x.ckpt'" "$D/err" | grep -Eiq "disk full|no space left" ||
    fail "full-disk checkpoint error names no file or reason: $(cat "$D/err")"
  [ "$(cat "$D/fleft")" = x.ckpt ] || fail "full disk: left on it: $(cat "$D/fleft")"
  [ "$(st_cmp meta "$D/fb.ckpt" train.iteration)" = 5 ] ||
    fail "full disk: the checkpoint kept is at iteration $(st_cmp meta "$D/fb.ckpt" train.iteration), not 5"
  [ ! -e "$D/fb.safetensors" ] || fail "full disk: a model was written by a failed run"
  for f in "$D"/*.tmp.* "$D"/.*.tmp.*; do
    [ ! -e "$f" ] || fail "full disk: temporary file left: $f"
  done
  tr_run --iters 20 --ckpt-every 5 -o "$D/fb.safetensors" --ckpt "$D/fb.ckpt" --resume 2>"$D/log" ||
    fail "resume from the checkpoint a full disk left: $(cat "$D/log")"
  tr_run --iters 20 --ckpt-every 5 -o "$D/fu.safetensors" 2>"$D/log" || fail "20 iterations: $(cat "$D/log")"
  st_cmp same "$D/fu.safetensors" "$D/fb.safetensors" || fail "full disk, resumed: the model differs"
  st_cmp same "$D/fu.safetensors.ckpt" "$D/fb.ckpt" || fail "full disk, resumed: the checkpoint differs"
  cut -d, -f1-4 "$D/fu.safetensors.csv" >"$D/fu.cols"
  cut -d, -f1-4 "$D/fb.safetensors.csv" >"$D/fb.cols"
  cmp -s "$D/fu.cols" "$D/fb.cols" || fail "full disk, resumed: the CSV differs: $(diff "$D/fu.cols" "$D/fb.cols")"
fi
# (2) the first periodic save cannot be written (a file-size limit below a checkpoint's size,
# SIGXFSZ ignored so the write fails with EFBIG; no privilege needed): an earlier run's model,
# checkpoint and CSV under those names stay as they were (the CSV is written under a temporary
# name until the first checkpoint), and nothing else is left. ulimit -f counts 512-byte
# blocks in dash, 1024-byte in bash: C/2048 blocks is below one checkpoint either way
mkdir "$D/ul" "$D/ul0"
tr_run --iters 20 --ckpt-every 5 -o "$D/ul/m.safetensors" 2>"$D/log" || fail "earlier run: $(cat "$D/log")"
cp -p "$D/ul/m.safetensors" "$D/ul/m.safetensors.ckpt" "$D/ul/m.safetensors.csv" "$D/ul0"
ls -A "$D/ul" >"$D/ul.before"
(
  trap '' XFSZ
  ulimit -f $((C / 2048)) || exit 97
  exec "$K" --store "$D/p.kps" --preset tiny --batch 2 --patch 16 --plot '' --threads 2 \
    --iters 20 --ckpt-every 5 --seed 2 -o "$D/ul/m.safetensors"
) 2>"$D/err"
rc=$?
[ $rc -eq 1 ] || fail "checkpoint over the file-size limit: exit $rc, not 1: $(cat "$D/err")"
grep -qF "checkpoint '$D/ul/m.safetensors.ckpt'" "$D/err" ||
  fail "unwritable checkpoint: the error names no file: $(cat "$D/err")"
# the system's reason, not a guess ("disk full?" was printed for every failure until session 62)
grep -qi "file too large" "$D/err" && ! grep -qi "disk full" "$D/err" ||
  fail "checkpoint over the file-size limit: the error does not give the system's reason: $(cat "$D/err")"
for f in m.safetensors m.safetensors.ckpt m.safetensors.csv; do
  cmp -s "$D/ul0/$f" "$D/ul/$f" || fail "a failed checkpoint save changed the earlier run's $f"
done
ls -A "$D/ul" | cmp -s - "$D/ul.before" || fail "a failed checkpoint save left: $(ls -A "$D/ul")"
# --- resume checks added in session 63 (one thread: determinism holds for one thread count).
# st_set SRC DST KEY=VALUE...: a copy of a checkpoint with metadata values replaced (the
# header rewritten, its 8-byte little-endian length set again, padded with spaces to 8 bytes;
# tensor offsets count from the header's end, so the data stays valid)
st_set() {
  /usr/bin/python3 - "$@" <<'PYEOF'
import json, struct, sys
b = open(sys.argv[1], "rb").read()
n = struct.unpack("<Q", b[:8])[0]
h = json.loads(b[8:8 + n])
for kv in sys.argv[3:]:
    k, v = kv.split("=", 1)
    h["__metadata__"][k] = v
j = json.dumps(h, separators=(",", ":")).encode()
j += b" " * (-len(j) % 8)
open(sys.argv[2], "wb").write(struct.pack("<Q", len(j)) + j + b[8 + n:])
PYEOF
}
tr1() { "$K" --store "$D/p.kps" --preset tiny --batch 2 --patch 16 --plot '' --threads 1 "$@"; }
# (1) the source score's learning rate is part of the run: a resume with another
# --source-lr-scale is refused naming train.source_lr_scale and the option, the checkpoint kept;
# the same one resumes
tr1 --source-weight --source-lr-scale 2 --iters 4 --csv '' -o "$D/sl.safetensors" 2>"$D/log" ||
  fail "--source-lr-scale 2: $(cat "$D/log")"
cp "$D/sl.safetensors.ckpt" "$D/sl0.ckpt"
tr1 --source-weight --source-lr-scale 3 --iters 8 --csv '' -o "$D/sl.safetensors" --resume 2>"$D/err"
rc=$?
[ $rc -eq 1 ] || fail "resume with another --source-lr-scale: exit $rc (want 1): $(cat "$D/err")"
grep -qF "train.source_lr_scale = 2, this run uses 3 (--source-lr-scale)" "$D/err" ||
  fail "--source-lr-scale mismatch unclear: $(cat "$D/err")"
cmp -s "$D/sl0.ckpt" "$D/sl.safetensors.ckpt" || fail "a refused resume changed the checkpoint"
tr1 --source-weight --source-lr-scale 2 --iters 8 --csv '' -o "$D/sl.safetensors" --resume 2>"$D/log" ||
  fail "resume with the same --source-lr-scale: $(cat "$D/log")"
# (2) the checkpoint records the best model kept (train.best_val / train.best_by), so that a
# resume without a CSV keeps comparing against it. Stage 2 at a 10x learning rate makes every
# validation after iteration 40 worse than the best at 40 (0.17 against 0.055 here): an
# uninterrupted run keeps iteration 40's model; a resume from 40 must too (it wrote the
# worse model at 50, 60, 70 when the best was taken from a CSV that --csv '' turned off)
tb() { tr1 --stage1-iters 40 --lr2 1e-2 --val "$N,$R" --val-every 10 "$@"; }
tb --iters 80 --csv '' -o "$D/bu.safetensors" --best "$D/bu.best" 2>"$D/log" ||
  fail "80 iterations with --best: $(cat "$D/log")"
grep -q "best model so far .* at iteration 40$" "$D/log" &&
  ! grep -q "best model so far .* at iteration [5-8]0$" "$D/log" ||
  fail "--best check set-up: the best model is not iteration 40's: $(cat "$D/log")"
tb --iters 40 --csv '' -o "$D/br.safetensors" --best "$D/br.best" 2>"$D/log" ||
  fail "40 iterations with --best: $(cat "$D/log")"
[ "$(st_cmp meta "$D/br.safetensors.ckpt" train.best_by)" = mean ] &&
  awk -v b="$(st_cmp meta "$D/br.safetensors.ckpt" train.best_val)" 'BEGIN { exit !(b + 0 > 0) }' ||
  fail "checkpoint records no best model: train.best_val '$(st_cmp meta "$D/br.safetensors.ckpt" train.best_val)'"
tb --iters 80 --csv '' -o "$D/br.safetensors" --best "$D/br.best" --resume 2>"$D/log" ||
  fail "resume to 80 with --best: $(cat "$D/log")"
! grep -q "best model so far" "$D/log" || fail "resume without a CSV replaced the best model by a worse one: $(cat "$D/log")"
st_cmp same "$D/bu.best" "$D/br.best" || fail "resumed at 40: the best model differs from the uninterrupted run's"
st_cmp same "$D/bu.safetensors.ckpt" "$D/br.safetensors.ckpt" ||
  fail "resumed at 40 with --best: the checkpoint differs from the uninterrupted run's"
# a run without --best records "none"; --best on its resume says so and keeps the best from
# there (it compared against the CSV's best validation row and wrote no best model here)
tb --iters 40 -o "$D/bn.safetensors" 2>"$D/log" || fail "40 iterations without --best: $(cat "$D/log")"
[ "$(st_cmp meta "$D/bn.safetensors.ckpt" train.best_val)" = none ] ||
  fail "no --best: train.best_val is '$(st_cmp meta "$D/bn.safetensors.ckpt" train.best_val)', not none"
tb --iters 80 -o "$D/bn.safetensors" --best "$D/bn.best" --resume 2>"$D/log" ||
  fail "resume with --best: $(cat "$D/log")"
grep -qF "no best model was kept before iteration 40: '$D/bn.best' will hold the best from here on" "$D/log" ||
  fail "resume with a new --best does not say so: $(cat "$D/log")"
grep -qF "written to '$D/bn.best' at iteration 50" "$D/log" && [ -e "$D/bn.best" ] ||
  fail "resume with a new --best wrote no best model at its first validation: $(cat "$D/log")"
# a session without --best between two with it passes the record on: the third session does
# not replace iteration 40's best model by a worse one
tb --iters 40 --csv '' -o "$D/bp.safetensors" --best "$D/bp.best" 2>"$D/log" || fail "bp 40: $(cat "$D/log")"
tb --iters 60 --csv '' -o "$D/bp.safetensors" --resume 2>"$D/log" || fail "bp 60: $(cat "$D/log")"
[ "$(st_cmp meta "$D/bp.safetensors.ckpt" train.best_val)" = \
  "$(st_cmp meta "$D/br.safetensors.ckpt" train.best_val)" ] ||
  fail "a session without --best dropped the best record: '$(st_cmp meta "$D/bp.safetensors.ckpt" train.best_val)'"
tb --iters 80 --csv '' -o "$D/bp.safetensors" --best "$D/bp.best" --resume 2>"$D/log" ||
  fail "bp 80: $(cat "$D/log")"
! grep -q "best model so far" "$D/log" && st_cmp same "$D/bu.best" "$D/bp.best" ||
  fail "after a session without --best, the best model was replaced: $(cat "$D/log")"
# (3) metadata out of range or malformed is refused (exit 1) naming the key, nothing written;
# the same checkpoint with its header rewritten but no value changed resumes (the control)
tr1 --iters 4 --csv '' -o "$D/m4.safetensors" 2>"$D/log" || fail "4 iterations: $(cat "$D/log")"
for kv in train.iteration=4 train.iteration=-5 train.rng=zz train.elapsed_s=abc train.seed=1xyz \
  train.adam_steps.diffuse=-1 train.adam_steps.specular=5; do
  rm -f "$D/mr.safetensors"
  st_set "$D/m4.safetensors.ckpt" "$D/bad.ckpt" "$kv" || fail "st_set $kv"
  tr1 --iters 8 --csv '' -o "$D/mr.safetensors" --ckpt "$D/bad.ckpt" --resume 2>"$D/err"
  rc=$?
  if [ "$kv" = train.iteration=4 ]; then
    [ $rc -eq 0 ] || fail "a checkpoint with its header rewritten as it was is refused: $(cat "$D/err")"
    continue
  fi
  [ $rc -eq 1 ] || fail "checkpoint with $kv: exit $rc (want 1): $(cat "$D/err")"
  grep -F "'${kv%%=*}'" "$D/err" | grep -Eq "malformed|out of range" ||
    fail "checkpoint with $kv: not refused as malformed: $(cat "$D/err")"
  [ ! -e "$D/mr.safetensors" ] || fail "a model written from a checkpoint with $kv"
done
# (4) another store: another patch count (the draws differ) is refused naming train.store and
# --store; images at another exposure, naming the architecture's field that differs
"$T" "$N" "$R" --patches:size=16:count=8:cull=1:out="$D/p8.kps" >/dev/null || fail "patches count 8"
oiiotool "$N" --mulc 4 -o "$D/n4.exr" && oiiotool "$R" --mulc 4 -o "$D/r4.exr" || fail "scaled images"
"$T" "$D/n4.exr" "$D/r4.exr" --patches:size=16:count=6:cull=1:out="$D/p4.kps" >/dev/null || fail "patches x4"
cp "$D/m4.safetensors.ckpt" "$D/m40.ckpt"
resume_on() { # STORE WHAT NEEDLE (grep -E): the resume exits 1 with NEEDLE in its message
  "$K" --store "$1" --preset tiny --batch 2 --patch 16 --plot '' --threads 1 --iters 8 --csv '' \
    -o "$D/m4.safetensors" --resume 2>"$D/err"
  rc=$?
  [ $rc -eq 1 ] || fail "resume on $2: exit $rc (want 1): $(cat "$D/err")"
  grep -qE "$3" "$D/err" || fail "resume on $2: message unclear: $(cat "$D/err")"
}
resume_on "$D/p8.kps" "a store of 8 patches" \
  "train.store = 6 patches of 16 px, 33 channels, 1 sources, this run uses 8 patches of 16 px, 33 channels, 1 sources \(--store\)"
resume_on "$D/p4.kps" "a store at 4x the exposure" \
  "kpcn.architecture's exposure: .* in the checkpoint, .* in this run \(another --store\?\)"
cmp -s "$D/m40.ckpt" "$D/m4.safetensors.ckpt" || fail "a resume on another store changed the checkpoint"
# (5) a run stopped right on a CSV row (--log-every 1: every iteration is one) ends with a
# validation row with no rate (an empty its_per_s cell, as the loss's: 0 was written), which
# --compare --y its_per_s plots (it refused the 0 on its log axis)
tr1 --iters 20000 --time-limit 0.005 --log-every 1 --val "$N,$R" -o "$D/tc.safetensors" 2>"$D/log" ||
  fail "--time-limit with --log-every 1: $(cat "$D/log")"
stop=$(sed -n 's/.*time limit reached at iteration \([0-9]*\): checkpointing$/\1/p' "$D/log")
[ -n "$stop" ] && [ "$stop" -gt 0 ] && [ "$stop" -lt 20000 ] || fail "--time-limit did not stop the run: $(cat "$D/log")"
tail -n 2 "$D/tc.safetensors.csv" | awk -F, -v s="$stop" '
  NR == 1 && !($1 == s && $5 != "" && $7 == "") { exit 1 }
  NR == 2 && !($1 == s && $4 == "" && $5 == "" && $7 != "") { exit 1 }' ||
  fail "stopped at $stop: the last rows are not a log row and a validation row without a rate: $(tail -n 2 "$D/tc.safetensors.csv")"
"$K" --compare "$D/ips.png" --y its_per_s a="$D/tc.safetensors.csv" 2>"$D/err" ||
  fail "--compare --y its_per_s of a run stopped on a row: $(cat "$D/err")"
[ -s "$D/ips.png" ] || fail "--compare --y its_per_s wrote no plot"
# the developer scripts without validation pairs: they passed kpcn-train's --val-from-store,
# refused since session 57, and so failed after their set-up; now they ask for pairs or
# VAL_STORE before doing anything (exit 2, no work folder made)
S=$(cd "$(dirname "$0")/../../tools/kpcn-train" && pwd)
for sc in ship_model.sh experiments.sh; do
  # ship_model.sh STORE [pairs]; experiments.sh STORE OUTDIR [pairs]
  if [ $sc = ship_model.sh ]; then set -- "$D/p.kps"; else set -- "$D/p.kps" "$D/expout"; fi
  KPCN_TRAIN=$K WORK=$D/shipwork bash "$S/$sc" "$@" 2>"$D/err" >/dev/null
  rc=$?
  [ $rc -eq 2 ] && grep -q "give validation pairs (NOISY.exr,REF.exr) or VAL_STORE=VAL.kps" "$D/err" &&
    [ ! -e "$D/shipwork" ] && [ ! -e "$D/expout" ] ||
    fail "$sc without validation: exit $rc (want 2): $(cat "$D/err")"
done
echo "test_train_cli: ok"
