# kpcntool stack commands: -o, --ch, --info, --errormap, --mosaic, --help.
. "$(dirname "$0")/lib.sh"
# --help lists every registered command (metrics, core; others' when built in).
run_ok --help
for c in --ssim --relmse --l1 --mse --rell1 --psnr --errormap --info --ch --ociodisplay --mosaic -o --json --threads; do
  grep -qE -- "^  $c( |$)" out.txt || fail "--help lacks $c"
done
pass "--help lists the commands"
# --info: AOV buffers under canonical names, kpcn:* attributes, size.
run_ok "$NOISY" --info
for s in "256x256" "16 channels" "buffer color: R,G,B  variance: color.var" "buffer albedo" \
  "buffer normal: N.X,N.Y,N.Z" "buffer depth: Z" "buffer visibility" "kpcn:spp: 16"; do
  grep -qF "$s" out.txt || fail "--info lacks '$s': $(cat out.txt)"
done
pass "--info text"
run_ok "$NOISY" --info --json
$PY -c 'import json,sys; d=json.load(open(sys.argv[1]))["info"]
assert d["width"]==256 and d["height"]==256 and d["kpcn:spp"]==16, d
assert set(d["buffers"])=={"color","albedo","normal","depth","visibility"}, d["buffers"]' out.txt \
  && pass "--info json" || fail "--info json: $(cat out.txt)"
# the albedo's provenance (kpcn-render --albedo-spp / --albedo-footprint) is shown when present
$PY -c 'import OpenImageIO as oiio, sys
b = oiio.ImageBuf(sys.argv[1]); s = b.spec()
s.attribute("kpcn:albedoSpp", 64); s.attribute("kpcn:albedoFootprint", 2)
b.write("attrs.exr")' "$NOISY"
run_ok attrs.exr --info
grep -qF "kpcn:albedoSpp: 64" out.txt && grep -qF "kpcn:albedoFootprint: 2" out.txt &&
  pass "--info shows the albedo attributes" || fail "--info albedo attributes: $(cat out.txt)"
run_ok "$NOISY" --info
! grep -q "kpcn:albedo" out.txt && pass "--info: no albedo attributes when absent" ||
  fail "--info shows absent attributes: $(cat out.txt)"
# --ch selects (and renames) channels; -o writes float EXR; reading it back gives the same metric.
run_ok "$NOISY" --ch R,G,B -o rgb.exr
run_ok rgb.exr --info
grep -qF "3 channels (R,G,B), float" out.txt && pass "-o wrote RGB float" || fail "rgb.exr: $(cat out.txt)"
run_ok rgb.exr "$REF" --relmse --json
grep -q '"relmse": 0.01062301168178' out.txt && pass "round trip keeps values" || fail "$(cat out.txt)"
run_ok "$NOISY" --ch R=albedo.R,G=albedo.G,B=albedo.B,A=1 -o alb.exr
run_ok alb.exr --info
grep -qF "4 channels (R,G,B,A)" out.txt && pass "--ch rename + constant" || fail "alb: $(cat out.txt)"
run_ok "$NOISY" --ch R=albedo.R,G=albedo.G,B=albedo.B alb.exr --l1:channels=R,G,B --json
grep -q '"l1": 0}' out.txt && pass "renamed channels hold the source values" || fail "$(cat out.txt)"
# --errormap pops two, pushes the per-pixel map; its mean is the metric.
run_ok "$NOISY" "$REF" --errormap:metric=relmse -o map.exr
oiiotool --pattern constant:color=0,0,0 256x256 3 -o zero.exr
run_ok map.exr zero.exr --l1 --json
cp out.txt em.json
near "$(json_get em.json l1)" 0.010623011681784554 1e-9 && pass "errormap mean == relmse" ||
  fail "errormap: $(cat out.txt)"
run_ok "$NOISY" "$REF" --errormap:metric=ssim:display=srgb --info
grep -qF "3 channels (R,G,B)" out.txt && pass "ssim errormap on stack" || fail "$(cat out.txt)"
# -o twice in one chain: both written; --ociodisplay + PNG gives 8 bit.
run_ok "$NOISY" --ch R,G,B -o a.exr --ociodisplay -o a.png
oiiotool --info a.png | grep -q "uint8" && [ -f a.exr ] && pass "png is 8 bit" || fail "png: $(oiiotool --info a.png)"
# --mosaic pastes n images side by side (labels need a font; a missing one only warns).
run_ok "$NOISY" --ch R,G,B "$REF" "$REF" --mosaic:labels=noisy,ref,ref2 -o mosaic.exr
run_ok mosaic.exr --info
grep -qF "768x256, 3 channels" out.txt && pass "mosaic size" || fail "mosaic: $(cat out.txt)"
run_ok "$NOISY" --ch R,G,B "$REF" --mosaic:n=2 --info
grep -qF "512x256" out.txt && pass "mosaic n=2" || fail "$(cat out.txt)"
# a label wider than its tile is cut off by the next tile: said, naming it (256-px tiles fit
# "ref" at the default size, not a 60-character label)
run_ok "$REF" "$REF" --mosaic:labels=ref,$(printf 'w%.0s' $(seq 60)) -o wide.exr
grep -q "warning: --mosaic: label 'w*' needs [0-9]* px at fontsize 16, its 256-px tile has 252" err.txt &&
  ! grep -q "label 'ref'" err.txt && pass "wide label warned" || fail "wide label: $(cat err.txt)"
# A missing font only costs the labels: warning, exit 0, mosaic written.
run_ok "$REF" "$REF" --mosaic:labels=a,b:font=NoSuchFont -o nofont.exr
grep -q "warning: --mosaic: labels not drawn" err.txt && [ -f nofont.exr ] && pass "font fallback" ||
  fail "font fallback: $(cat err.txt)"
# A font larger than the tile: OIIO's render_text aborted the process (found by fuzzing); now
# the labels are skipped with a warning naming the size, and the mosaic is written.
# --render: the pixels kpcn-render writes (every channel), in a chain with --denoise and a
# metric; its errors name the problem and write nothing
SC=$TD/scenes/cornell-box/scene.json
KR=$(dirname "$KT")/../kpcn-render/kpcn-render
if [ -x "$KR" ]; then
  run_ok --render:spp=4:res=32x24:seed=3 "$SC" -o rr.exr
  "$KR" "$SC" -o kr.exr --spp 4 --resolution 32x24 --seed 3 --quiet
  idiff -fail 0 -warn 0 -a rr.exr kr.exr > /dev/null && pass "--render = kpcn-render" ||
    fail "--render differs from kpcn-render"
  run_ok --render:spp=4:res=32x24 "$SC" --denoise:method=nlmeans \
    --render:spp=64:res=32x24:seed=9 "$SC" --relmse --json
  $PY -c 'import json,sys; v=json.load(open(sys.argv[1]))["relmse"]; assert 0 < v < 1' out.txt &&
    pass "render, denoise, measure in one chain" || fail "chain: $(cat out.txt)"
  expect_fail "cannot open scene 'nope.json'" x.exr --render:spp=2 nope.json -o x.exr
  expect_fail "crop 30,0,8,8 lies outside the 32x24 image" x.exr \
    --render:res=32x24:crop=30,0,8,8 "$SC" -o x.exr
  expect_fail "res must be WxH" x.exr --render:res=32 "$SC" -o x.exr
  expect_fail "res must be WxH" x.exr --render:res=4294967312x24 "$SC" -o x.exr
  expect_fail "crop must be x,y,w,h" x.exr --render:res=32x24:crop=-0,0,8,8 "$SC" -o x.exr
fi
oiiotool "$REF" --cut 0,0,23,23 -o tile24.exr
run_ok tile24.exr tile24.exr --mosaic:labels=a,b:fontsize=90 -o big.exr
grep -qF "fontsize 90 does not fit a 24x24 tile" err.txt && [ -f big.exr ] && pass "oversized labels" ||
  fail "oversized labels: $(cat err.txt)"
# --ch as oiiotool: bare numbers are channel indices, blanks around items are dropped, a
# number after '=' stays a constant
run_ok "$NOISY" --ch "2, 1,0" --info
grep -qF "3 channels (B,G,R)" out.txt && pass "--ch by index" || fail "--ch 2,1,0: $(cat out.txt)"
run_ok "$NOISY" --ch "R, G ,B" "$NOISY" --ch 0,1,2 --l1 --json
grep -q '"l1": 0}' out.txt && pass "indices == names" || fail "indices: $(cat out.txt)"
expect_fail "has no channel '99' (channel indices are 0 to" x.exr "$NOISY" --ch 99 -o x.exr
# after '=' a number is a constant even where a channel has that name
oiiotool --pattern constant:color=0.3,0.6 2x2 2 --chnames 0,1 -o named01.exr
run_ok named01.exr --ch X=0 --json --info
grep -q '"X"' out.txt && pass "X=0 parsed" || fail "X=0: $(cat out.txt)"
oiiotool --pattern constant:color=0 2x2 1 --chnames X -o zero1.exr
run_ok named01.exr --ch X=0 zero1.exr --l1 --json
grep -q '"l1": 0}' out.txt && pass "X=0 is the constant 0, not channel '0'" || fail "X=0: $(cat out.txt)"
# As oiiotool: an -o file keeps the input files' pixel type (the widest of them) as far as its
# format holds it, -d sets it; more than 4 channels only to EXR/TIFF; a crop (data window
# inside a larger frame) keeps its frame: PNG pads it with black, --mosaic tiles the frame,
# mirrors and quarter turns move it inside the frame like --flop/--flip/--rotate90.
oiiotool --pattern fill:left=0.1,0.2,0.3:right=0.9,0.5,0.1 40x30 3 -d uint8 -o u8.tif \
  -d uint16 -o u16.png -d half -o h.exr
run_ok u8.tif -o u8o.tif u16.png -o u16o.png h.exr --ch R,G -o h2.exr -d float -o f.exr
for f in u8o.tif:uint8 u16o.png:uint16 h2.exr:half f.exr:float; do
  oiiotool --info "${f%%:*}" | grep -q "${f#*:} " && pass "type ${f#*:} kept/set" ||
    fail "type of ${f%%:*}: $(oiiotool --info "${f%%:*}")"
done
run_ok u8.tif u16.png --mosaic -o mix.png
oiiotool --info mix.png | grep -q "uint16 png" && pass "computed: widest input type" || fail "$(oiiotool --info mix.png)"
# an image as read keeps its own file's type, whatever else was read (as oiiotool)
run_ok h.exr u16.png -o own16.png h.exr u8.tif -o own8.tif
oiiotool --info own16.png | grep -q "uint16 png" && oiiotool --info own8.tif | grep -q "uint8 tiff" &&
  pass "as read: its own type" || fail "own types: $(oiiotool --info own16.png own8.tif)"
# PNM holds 16 bits: the input's uint16 and -d uint16 reach the file's maximum value (OIIO's PNM
# writer takes its depth from oiio:BitsPerSample, so both came out 8-bit until session 62)
run_ok u16.png -o k16.ppm u8.tif -o k8.ppm --ch R -d uint16 -o d16.pgm
for f in k16.ppm:65535 d16.pgm:65535 k8.ppm:255; do
  [ "$(head -c 20 "${f%%:*}" | tr '\n' ' ' | awk '{print $4}')" = "${f#*:}" ] &&
    pass "${f%%:*}: maximum value ${f#*:}" || fail "${f%%:*}: header $(head -c 20 "${f%%:*}" | tr '\n' ' ')"
done
# the samples as stored (big-endian after the header) against the PNG's: OIIO's PNM reader
# converts some 16-bit values a step low, so the file is read here
if $PY - <<'PY'; then pass "16-bit PPM holds the PNG's values exactly"; else fail "16-bit PPM values"; fi
import numpy as np, OpenImageIO as oiio
png = oiio.ImageBuf("u16.png").get_pixels(oiio.UINT16)
raw = open("k16.ppm", "rb").read()
assert raw.startswith(b"P6\n40 30\n65535\n"), raw[:20]
ppm = np.frombuffer(raw[len(b"P6\n40 30\n65535\n"):], dtype=">u2").reshape(png.shape)
assert (ppm == png).all(), (ppm != png).sum()
PY
# --mosaic labels that do not fit the (short) tile: none drawn, a warning naming the tile
oiiotool --pattern constant:color=0,0,0 20x12 3 -o short.exr --pattern constant:color=0,0,0 40x30 3 -o tall.exr
run_ok short.exr tall.exr --mosaic:labels=a,b:fontsize=20 -o lab.exr
grep -q "labels not drawn (fontsize 20 does not fit a 20x12 tile)" err.txt &&
  oiiotool --stats lab.exr | grep -q 'Max: 0.000000 0.000000 0.000000' &&
  pass "--mosaic: labels taller than a tile are not drawn, with a warning" ||
  fail "--mosaic short tile: $(cat err.txt) $(oiiotool --stats lab.exr | grep Max)"
# DPX holds 1, 3 or 4 channels (OIIO's writer aborted on others, leaving temporaries)
expect_fail ".dpx files hold 1, 3 or 4" x.dpx h.exr --ch R,G -o x.exr -o x.dpx
[ ! -e x.exr ] || fail "x.exr written beside a refused DPX"
expect_fail "pixel type 'int' is not one of uint8, uint16, half, float" x.exr h.exr -d int -o x.exr
expect_fail "and .png files hold at most 4: select them first (--ch R,G,B)" x.png "$NOISY" -o x.png
expect_fail "and .jpg files hold at most 4" x.jpg "$NOISY" -o x.jpg
oiiotool --pattern fill:left=0.1,0.2,0.3:right=0.9,0.5,0.1 40x30 3 --origin +5+7 --fullsize 60x50 \
  -o dw.exr
# a display window far beyond the pixels (a 16x16 header saying 60000x60000) cannot be filled:
# refused by name for PNG and --mosaic (OIIO aborted), kept as it is in EXR
oiiotool --create 16x16 3 -d float --fullsize 60000x60000+0+0 -o huge_frame.exr
expect_fail "its display window is 60000x60000 (its pixels 16x16), too large to fill" x.png \
  huge_frame.exr -o x.png
expect_fail "image 1 (image 'huge_frame.exr'): its display window is 60000x60000" x.exr \
  huge_frame.exr huge_frame.exr --mosaic:n=2 -o x.exr
run_ok huge_frame.exr --ch R,G -o hf.exr
# a frame within the size limits whose filled copies cannot fit in memory: refused by name
oiiotool --create 4x4 64 -d half --fullsize 16384x16384+0+0 -o deep_frame.exr
expect_fail "too large to fill (68.7 GB of 64 channels, with the copies made to write it more than" \
  x.tif deep_frame.exr -o x.tif
# --mosaic of a frame that does not start at 0,0 (OIIO's paste ignored the origin: black)
oiiotool --pattern constant:color=0.5,0.25,1 16x12 3 --origin +10+20 --fullsize 16x12+10+20 -o shifted.exr
oiiotool shifted.exr --origin +0+0 --fullsize 16x12+0+0 -o shifted0.exr
run_ok shifted.exr --mosaic:n=1 shifted0.exr --l1 --json
grep -q '"l1": 0}' out.txt && pass "mosaic of a shifted frame" || fail "shifted mosaic: $(cat out.txt)"
run_ok dw.exr -o dw.png dw.exr --mosaic:n=1 -o dwm.exr
oiiotool dw.exr -o dw_oiio.png
idiff -fail 0 -warn 0 -a dw.png dw_oiio.png >/dev/null && pass "crop to PNG padded like oiiotool" ||
  fail "crop to PNG: $(oiiotool --info dw.png)"
oiiotool --info dwm.exr | grep -Eq "60 x +50," && pass "mosaic tiles the frame" || fail "$(oiiotool --info dwm.exr)"
for p in mirror:dir=h:flop mirror:dir=v:flip rotate:deg=90:rotate270 rotate:deg=270:rotate90; do
  kc=${p%:*} oc=${p##*:}
  run_ok dw.exr --$kc -o k_$oc.exr
  oiiotool dw.exr --$oc -o o_$oc.exr
  idiff -fail 0 -warn 0 -a k_$oc.exr o_$oc.exr >/dev/null &&
    [ "$(oiiotool --info -v k_$oc.exr | grep -i window)" = "$(oiiotool --info -v o_$oc.exr | grep -i window)" ] &&
    pass "--$kc == oiiotool --$oc (pixels and windows)" || fail "--$kc vs --$oc"
done
# The shipped model tiled and untiled: equal to float summation order, not bit for bit
# (oneDNN blocks its kernels by tensor shape; session 59 measured at most 1.6e-6 relative on a
# 97x61 image); bound 1e-5 of the pixel's value (+1e-7 absolute), and tile=16 does tile it.
if [ -x "$KR" ]; then
run_ok --render:spp=8:res=97x61 "$SC" -o n97.exr
run_ok n97.exr --denoise:model=$TD/models/kpcn-cpu.safetensors -o u97.exr n97.exr \
  --denoise:model=$TD/models/kpcn-cpu.safetensors:tile=16 -o t97.exr
if $PY - <<'PY'; then pass "tile=16 == untiled within 1e-5"; else fail "tile=16 vs untiled"; fi
import OpenImageIO as oiio, numpy as np
u, t = (oiio.ImageBuf(f).get_pixels(oiio.FLOAT) for f in ("u97.exr", "t97.exr"))
assert u.shape == (61, 97, 3), u.shape
d = np.abs(u - t) / (np.abs(u) * 1e-5 + 1e-7)
print("max |tiled - untiled| / bound:", d.max())
raise SystemExit(int(d.max() > 1))
PY
fi
finish
