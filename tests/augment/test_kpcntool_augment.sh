#!/bin/sh
# kpcntool augmentation commands against OpenImageIO's own oiiotool as independent truth:
# --mirror == oiiotool --flop with N.X negated; --rotate:deg=90 (counter-clockwise) ==
# oiiotool --rotate270 (oiiotool turns clockwise) with (N.X, N.Y) -> (-N.Y, N.X);
# colour swap and inverse round trips; patches written as EXR pairs and a store.
# usage: test_kpcntool_augment.sh KPCNTOOL SAMPLE_NOISY SAMPLE_REF TMPDIR
set -u
K=$1; N=$2; R=$3; T=$4
fails=0; checks=0
ok() { checks=$((checks+1)); if ! eval "$1"; then fails=$((fails+1)); echo "FAIL: $2" >&2; fi; }
same() { oiiotool --fail 0 --diff "$1" "$2" > /dev/null 2>&1; }
# same channels: IMG_A CHANNELS_A IMG_B CHANNELS_B [extra oiiotool ops on B] (one oiiotool run)
samech() { a=$1; ca=$2; b=$3; cb=$4; shift 4; oiiotool --fail 0 "$a" --ch "$ca" "$b" --ch "$cb" "$@" --diff > /dev/null 2>&1; }
rm -rf "$T"; mkdir -p "$T"
OTHER="R,G,B,N.Z,Z,albedo.R,albedo.G,albedo.B,diffuse.R,specular.B,visibility.V,color.var,N.var"

"$K" "$N" --mirror -o "$T/m.exr"
ok 'samech "$T/m.exr" "$OTHER" "$N" "$OTHER" --flop' "mirror moves pixels like oiiotool --flop"
ok 'samech "$T/m.exr" N.X "$N" N.X --flop --mulc -1' "mirror negates N.X"
ok 'samech "$T/m.exr" N.Y "$N" N.Y --flop' "mirror keeps N.Y"
"$K" "$N" --mirror:dir=v -o "$T/v.exr"
ok 'samech "$T/v.exr" N.Y "$N" N.Y --flip --mulc -1' "vertical mirror negates N.Y"
"$K" "$N" --rotate:deg=90 -o "$T/r.exr"
ok 'samech "$T/r.exr" "$OTHER" "$N" "$OTHER" --rotate270' "rotate 90 CCW moves pixels like oiiotool --rotate270"
ok 'samech "$T/r.exr" N.X "$N" N.Y --rotate270 --mulc -1' "rotate: N.X' = -N.Y"
ok 'samech "$T/r.exr" N.Y "$N" N.X --rotate270' "rotate: N.Y' = N.X"

"$K" "$N" --mirror --rotate:deg=90 --colorswap:perm=BRG --shift:dx=5:dy=-3 -o "$T/x.exr"
"$K" "$T/x.exr" --shift:dx=-5:dy=3 --colorswap:perm=GBR --rotate:deg=-90 --mirror -o "$T/y.exr"
ok 'same "$N" "$T/y.exr"' "chain and its inverse give the input back"
"$K" "$N" --colorswap:perm=BRG -o "$T/c.exr"
ok 'samech "$T/c.exr" R,albedo.R,specular.R,diffuse.G "$N" B,albedo.B,specular.B,diffuse.R' "colorswap BRG: new R = old B, new G = old R in every colour buffer"
ok '! samech "$T/c.exr" R "$N" R' "colorswap changed R (the comparison can fail)"
"$K" "$N" "$R" --augment:seed=4:shift=3 -o "$T/aug_ref.exr" > /dev/null
rc=$?
ok '[ $rc -eq 0 ]' "augment a pair"

"$K" "$N" "$R" --patches:size=8:count=6:seed=2:out="$T/pp" > "$T/p.out"
rc=$?
ok '[ $rc -eq 0 ] && [ -f "$T/pp/noisy_0005.exr" ] && [ -f "$T/pp/ref_0005.exr" ]' "patch EXR pairs"
ok 'grep -q "patches_kept: *6" "$T/p.out"' "kept count reported"
"$K" "$N" "$R" --patches:size=8:count=6:seed=2:out="$T/p.kps" > /dev/null
rc=$?
ok '[ $rc -eq 0 ] && [ -s "$T/p.kps" ]' "patch store"
"$K" "$N" --colorswap:perm=RGX -o "$T/bad.exr" 2> "$T/err"
rc=$?
ok '[ $rc -ne 0 ] && [ ! -e "$T/bad.exr" ] && grep -q RGX "$T/err"' "bad permutation"
"$K" "$N" "$R" --patches:size=100 2> "$T/err"
rc=$?
ok '[ $rc -ne 0 ] && grep -q "does not fit" "$T/err"' "patch larger than the image"
echo "kpcntool_augment: $checks checks, $((checks-fails)) passed, $fails failed"
[ $fails -eq 0 ]
