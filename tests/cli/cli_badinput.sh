# Bad images, channels, non-finite values, modifier values and OCIO settings: exit != 0, a
# message naming the problem, no output file, no temp file.
. "$(dirname "$0")/lib.sh"
oiiotool "$REF" --cut 0,0,127,127 -o small.exr
oiiotool --pattern constant:color=0.5,0.5,0.5 16x16 3 -o grey.exr
oiiotool --pattern constant:color=inf,0.5,0.5 8x4 3 --pattern constant:color=0.5,0.5,0.5 16x16 3 \
  --paste +0+0 -o inf.exr
oiiotool --pattern constant:color=nan,0.5,0.5 16x16 3 -o nan.exr
# A failure after an -o leaves no output either (outputs are written at the end).
expect_fail "image sizes differ ('$NOISY' is 256x256, 'small.exr' is 128x128)" out.exr \
  "$NOISY" -o out.exr small.exr --ssim
# Images and channels.
expect_fail "image sizes differ" map.exr "$NOISY" small.exr --errormap -o map.exr
expect_fail "has no channel 'Q'" "" "$NOISY" "$REF" --relmse:channels=R,Q
expect_fail "--errormap:channels=G,G: relmse: the channel list names 'G' twice" map.exr "$NOISY" "$REF" \
  --errormap:channels=G,G -o map.exr
expect_fail "channel counts differ (test image 1, reference 3)" "" "$NOISY" --ch R "$REF" --l1
expect_fail "is missing from the test image" "" "$NOISY" \
  --ch albedo.R,albedo.G,albedo.B "$REF" --l1
expect_fail "has no channel 'nope'" out.exr "$NOISY" --ch R,nope -o out.exr
expect_fail "needs two images on the stack" "" "$REF" --ssim
expect_fail "the image stack is empty" "" --info
oiiotool "$REF" --cut 0,0,7,7 -o tiny.exr
expect_fail "ssim: image of 8x8 is smaller than the 11x11 window" "" tiny.exr tiny.exr --ssim
# Non-finite values: an error naming the count unless allow_nonfinite=1.
expect_fail "32 pixel(s) hold NaN/Inf in 'inf.exr' or 'grey.exr'" map.exr inf.exr grey.exr \
  --errormap:metric=l1 -o map.exr
expect_fail "every one of the 256 pixels is non-finite" "" nan.exr grey.exr --l1:allow_nonfinite=1
# Modifier values.
expect_fail "modifier 'range' needs a finite number (got 'abc')" "" "$REF" "$REF" --psnr:range=abc
expect_fail "modifier 'tol' needs a finite number (got 'inf')" "" "$NOISY" "$REF" --patches:tol=inf
expect_fail "modifier 'eps' must be > 0 (got '0')" "" "$REF" "$REF" --relmse:eps=0
expect_fail "modifier 'dx' needs an integer in [-2147483648, 2147483647] (got '4294967297')" "" \
  "$REF" --shift:dx=4294967297
expect_fail "modifier 'seed' needs an integer in [0, 2^64-1] (got '-1')" "" "$NOISY" --augment:seed=-1
expect_fail "modifier 'allow_nonfinite' must be 0 or 1 (got 'maybe')" "" "$REF" "$REF" \
  --l1:allow_nonfinite=maybe
expect_fail "modifier 'bf16' must be 0 or 1 (got '5')" "" "$NOISY" --denoise:model=m.safetensors:bf16=5
expect_fail "modifier 'ensemble' applies only to the KPCN, not method=bilateral" "" "$NOISY" \
  --denoise:method=bilateral:ensemble=8
expect_fail "exposure must be auto, off or a number > 0 and < 1e30 that a float holds (got '1e-50')" "" "$NOISY" \
  --denoise:model=m.safetensors:exposure=1e-50
expect_fail "channel 'A': the constant 'nan' is not a finite decimal float" "" "$REF" --ch R,G,B,A=nan
expect_fail "channel name 'X' appears twice" "" "$REF" --ch X=R,X=G
expect_fail "modifier 'range' must be positive" "" "$REF" "$REF" --psnr:range=-1
expect_fail "modifier 'display' must be srgb or linear (got 'rec2020')" "" "$REF" "$REF" --ssim:display=rec2020
expect_fail "unknown metric 'foo'" "" "$REF" "$REF" --errormap:metric=foo
expect_fail "n=5 but the stack holds 2" "" "$REF" "$REF" --mosaic:n=5
expect_fail "fontsize=0 is outside [1, 1000]" "" "$REF" "$REF" --mosaic:labels=a,b:fontsize=0
expect_fail "thread count must be an integer" "" --threads many "$REF"
# OCIO.
expect_fail "view 'Nope' of display 'sRGB' is not in OCIO config" out.png "$REF" --ociodisplay:view=Nope -o out.png
expect_fail "display 'P3' is not in OCIO config" "" "$REF" --ociodisplay:display=P3
OCIO=$PWD/none.ocio expect_fail "OCIO config '$PWD/none.ocio' not found" "" "$REF" --ociodisplay
expect_fail "no R,G,B to display" "" "$NOISY" --ch N.X,N.Y,N.Z,Z,visibility.V --ociodisplay
expect_fail "look 'bogus' is not in OCIO config" out.png "$REF" --ociodisplay:looks=bogus -o out.png
# --info --json stays JSON for numeric attributes of any shape (NaN -> null, vectors -> arrays).
oiiotool "$REF" --attrib:type=float kpcn:spp nan --attrib:type=int[3] kpcn:seed "1,2,3" -o attr.exr
"$KT" attr.exr --info --json >attr.json 2>&1
if $PY -c 'import json,sys; d=json.load(open(sys.argv[1]))["info"]; sys.exit(0 if d["kpcn:spp"] is None and d["kpcn:seed"]==[1,2,3] else 1)' attr.json; then
  pass "--info --json: numeric attributes as JSON"
else
  fail "--info --json: $(cat attr.json)"
fi
# a deep EXR read as a flat image crashed the operations inside OIIO: refused by name
$PY -c '
import OpenImageIO as oiio
spec = oiio.ImageSpec(4, 4, 4, oiio.FLOAT)
spec.channelnames = ("R", "G", "B", "Z")
spec.deep = True
spec.z_channel = 3
buf = oiio.ImageBuf(spec)
dd = buf.deepdata()
for p in range(16):
    dd.set_samples(p, 1)
    for c, v in enumerate((0.5, 0.25, 0.125, 1.0 + p)):
        dd.set_deep_value(p, c, 0, v)
assert buf.write("deep.exr")'
expect_fail "is a deep image: deep images are not supported" "" deep.exr --relmse deep.exr
# a multi-part file (Blender's multilayer EXR) is read from its first part, with a warning
oiiotool "$REF" --ch R,G,B "$REF" --ch R,G,B --siappend -o parts.exr
"$KT" parts.exr --info >out.txt 2>err.txt
grep -q "warning: 'parts.exr' holds 2 parts (subimages); only the first, with 3 channels" err.txt &&
  pass "multi-part warning" || fail "multi-part: $(cat err.txt)"
# two --info in one --json object: two keys (a repeated key would leave one image's info to
# a JSON reader), the second suffixed as repeated metrics are
"$KT" attr.exr --info "$REF" --info --json >attr2.json 2>&1
if $PY -c 'import json,sys; d=json.load(open(sys.argv[1])); sys.exit(0 if sorted(d) == ["info", "info_2"] and d["info"]["kpcn:seed"] == [1,2,3] else 1)' attr2.json; then
  pass "--info twice: info and info_2"
else
  fail "--info twice: $(cat attr2.json)"
fi
# A channel name with an escape sequence and a byte that is not UTF-8: printed escaped, never
# raw (a damaged file must not drive the terminal or break the JSON's UTF-8).
oiiotool --pattern constant:color=1 4x4 1 --chnames "$(printf '\033[31mR\377')" -o esc.exr
"$KT" esc.exr --info >info.txt 2>&1
"$KT" esc.exr --info --json >>info.txt 2>&1
if grep -q "$(printf '\033')" info.txt || ! grep -qF '\x1b[31mR\xff' info.txt; then
  fail "raw control bytes printed: $(cat -v info.txt)"
else
  pass "file text printed escaped"
fi
# A colour map of an image with no finite pixel has nothing to scale by: said so.
expect_fail "every pixel of the image is NaN or Inf" out.png nan.exr --colormap -o out.png
# Two crops of one image at different offsets hold different pixels: not compared as a pair.
oiiotool "$REF" --crop 16x16+0+0 -o crop0.exr
oiiotool "$REF" --crop 16x16+24+24 -o crop24.exr
expect_fail "the images cover different pixels ('crop0.exr' has the data window 16x16+0+0, 'crop24.exr' 16x16+24+24)" \
  "" crop0.exr crop24.exr --l1
[ -z "$(ls -a | grep -E '\.tmp|^out\.(exr|png)$|^map\.exr$')" ] && pass "no stray outputs" || fail "stray: $(ls -a)"
finish
