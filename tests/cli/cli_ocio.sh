# --ociodisplay with the shipped config (testdata/ocio/config.ocio): pixel values against the
# analytic sRGB OETF and the tone curves the LUTs encode; $OCIO overrides the default.
. "$(dirname "$0")/lib.sh"
unset OCIO
# One 3x1 image holding three test colours; one kpcntool run makes all four views.
oiiotool --pattern constant:color=0,0.18,0.5 1x1 3 --pattern constant:color=1,2,-0.3 1x1 3 \
  --pattern constant:color=0.002,0.04,8 1x1 3 --mosaic 3x1 -o c.exr
run_ok c.exr --ociodisplay:display=sRGB:view=Standard -o o_Standard.exr \
  c.exr --ociodisplay:view=Reinhard -o o_Reinhard.exr c.exr --ociodisplay:view=Filmic -o o_Filmic.exr \
  c.exr --ociodisplay:display=sRGB:view=Raw -o o_Raw.exr
for v in Standard Reinhard Filmic Raw; do oiiotool --dumpdata o_$v.exr >dump_$v.txt; done
oiiotool --dumpdata c.exr >dump_in.txt
# Every output pixel against the analytic curve of its view.
if $PY - <<'PY'; then pass "display values match the analytic curves"; else fail "display values"; fi
import re
def px(f):
    return [list(map(float, m.split())) for m in re.findall(r"Pixel \(\d+, 0\): (.*)", open(f).read())]
def s(v):
    v = min(max(v, 0.0), 1.0)
    return 12.92 * v if v <= 0.0031308 else 1.055 * v ** (1 / 2.4) - 0.055
def h(v):
    A, B, C, D, E, F = 0.15, 0.5, 0.1, 0.2, 0.02, 0.3
    return ((v * (A * v + C * B) + D * E) / (v * (A * v + B) + D * F)) - E / F
curves = {"Standard": lambda x: s(x), "Reinhard": lambda x: s(max(x, 0) / (1 + max(x, 0))),
          "Filmic": lambda x: s(h(2 * max(x, 0)) / h(11.2)), "Raw": lambda x: x}
inp, bad = px("dump_in.txt"), 0
assert len(inp) == 3
for view, f in curves.items():
    tol = 2e-4 if view in ("Reinhard", "Filmic") else 1e-5  # 4096-entry LUT, linear interp.
    out = px("dump_%s.txt" % view)
    assert len(out) == 3, view
    for pi, po in zip(inp, out):
        for x, g in zip(pi, po):
            ok = abs(g - f(x)) <= tol
            print("%s %-8s(%g) = %.7f  expected %.7f" % ("ok  " if ok else "FAIL", view, x, g, f(x)))
            bad += not ok
raise SystemExit(bad)
PY
# Default display/view are sRGB/Standard.
run_ok c.exr --ociodisplay -o d.exr
run_ok d.exr o_Standard.exr --l1 --json
grep -q '"l1": 0}' out.txt && pass "default view is Standard" || fail "default: $(cat out.txt)"
# $OCIO overrides the default config (a copy with views renamed must be used).
sed 's/name: Standard,/name: PlainCopy,/; s/\[Standard, /[PlainCopy, /' "$TD/ocio/config.ocio" >alt.ocio
cp "$TD"/ocio/*.spi1d .
OCIO=$PWD/alt.ocio run_ok c.exr --ociodisplay:view=PlainCopy -o alt.exr
OCIO=$PWD/alt.ocio expect_fail "view 'Standard'" std.exr c.exr --ociodisplay:view=Standard -o std.exr
# AOV images: only R,G,B are transformed.
run_ok "$NOISY" --ociodisplay:view=Filmic -o aov.png
oiiotool --info aov.png | grep -q "3 channel" && pass "AOV -> RGB png" || fail "$(oiiotool --info aov.png)"
# --colormap against oiiotool's own colour maps: a ramp over [0, 2] with max=2 equals
# oiiotool's map of the ramp / 2; an RGB image maps its channel mean; the default max is the
# 99th percentile (a constant image maps to the top of the map).
oiiotool --pattern fill:left=0:right=2 9x1 1 -o ramp.exr
oiiotool ramp.exr --mulc 0.5 --colormap inferno -o ramp_oiio.exr
oiiotool ramp.exr --mulc 0.5 --colormap viridis -o ramp_oiio_v.exr
oiiotool --pattern constant:color=0.1,0.2,0.6 4x2 3 -o rgb.exr
oiiotool --pattern constant:color=0.3 4x2 1 --colormap inferno -o rgb_oiio.exr
oiiotool --pattern constant:color=1 4x2 1 --colormap inferno -o top_oiio.exr
run_ok ramp.exr --colormap:max=2 ramp_oiio.exr --l1 --json
grep -q '"l1": 0}' out.txt && pass "colormap inferno == oiiotool" || fail "colormap: $(cat out.txt)"
run_ok ramp.exr --colormap:max=2:map=viridis ramp_oiio_v.exr --l1 --json
grep -q '"l1": 0}' out.txt && pass "colormap viridis == oiiotool" || fail "viridis: $(cat out.txt)"
run_ok rgb.exr --colormap:max=1 rgb_oiio.exr --l1 --json
$PY -c 'import json,sys; sys.exit(json.load(open("out.txt"))["l1"] > 1e-6)' &&
  pass "colormap of RGB = map of the channel mean" || fail "rgb mean: $(cat out.txt)"
run_ok rgb.exr --colormap top_oiio.exr --l1 --json
grep -q '"l1": 0}' out.txt && pass "colormap default max = 99th percentile" || fail "auto max: $(cat out.txt)"
expect_fail "colour map 'nope'" cm.png ramp.exr --colormap:map=nope -o cm.png
expect_fail "modifier 'max' must be positive" cm.png ramp.exr --colormap:max=0 -o cm.png
oiiotool --pattern constant:color=0 4x2 1 -o zero.exr
expect_fail "give a positive :max=" cm.png zero.exr --colormap -o cm.png
# from= defaults to the image's own colour space, as in oiiotool: an 8-bit sRGB PNG through
# the Standard view comes back as it was (it used to be encoded a second time); one tagged
# with a space the config lacks is an error asking for from=.
oiiotool --pattern fill:left=0.05,0.3,0.6:right=0.9,0.5,0.1 16x4 3 -d uint8 -o s8.png
run_ok s8.png --ociodisplay -o s8d.exr
OCIO=$TD/ocio/config.ocio oiiotool s8.png --ociodisplay sRGB Standard -o s8o.exr
idiff -fail 1e-6 -a s8d.exr s8o.exr >/dev/null && pass "from= defaults to the PNG's sRGB, as oiiotool" ||
  fail "default from: $(idiff -a s8d.exr s8o.exr)"
run_ok s8.png --ociodisplay:from=scene_linear s8.png --ociodisplay --l1 --json
$PY -c 'import json,sys; sys.exit(json.load(open("out.txt"))["l1"] < 0.05)' &&
  pass "from=scene_linear still encodes it" || fail "explicit from: $(cat out.txt)"
oiiotool s8.png --attrib oiio:ColorSpace GammaCorrected1.8 -o g18.png
expect_fail "tagged as colour space 'GammaCorrected1.8' (oiio:ColorSpace), which OCIO config" x.exr \
  g18.png --ociodisplay -o x.exr
# An AOV image (any channel besides R, G, B, A) is reduced to its colour first: a Z after R,G,B
# was displayed as alpha until session 62, and an R,G,Z image is refused
oiiotool --pattern constant:color=0.1,0.2,0.3,5 8x8 4 --chnames R,G,B,Z -o rgbz.exr
oiiotool --pattern constant:color=0.1,0.2,0.3 8x8 3 -o rgb.exr
run_ok rgbz.exr --ociodisplay -o drgbz.exr rgb.exr --ociodisplay -o drgb.exr
oiiotool --info drgbz.exr | grep -q ", 3 channel," && idiff -fail 0 -a drgbz.exr drgb.exr >/dev/null &&
  pass "--ociodisplay of R,G,B,Z = of R,G,B" || fail "R,G,B,Z display: $(oiiotool --info -v drgbz.exr | head -3)"
oiiotool rgbz.exr --ch R,G,Z -o rgz.exr
expect_fail "has 3 channels but no R,G,B to display" x.exr rgz.exr --ociodisplay -o x.exr
# looks= are applied (OIIO 2.4's display transform ignores them): a config with a look
# 'Brighten' (exponent 0.5 in linear) against oiiotool's --ociolook then --ociodisplay.
sed 's/^active_views:.*/&\nlooks:\n  - !<Look>\n    name: Brighten\n    process_space: Linear Rec.709 (sRGB)\n    transform: !<ExponentTransform> {value: [0.5, 0.5, 0.5, 1]}/' \
  "$TD/ocio/config.ocio" >looks.ocio
run_ok c.exr --ociodisplay:config=looks.ocio:looks=Brighten -o lk.exr c.exr \
  --ociodisplay:config=looks.ocio -o nolk.exr
oiiotool --colorconfig looks.ocio c.exr --ociolook:from=scene_linear:to=scene_linear Brighten \
  --ociodisplay:from=scene_linear sRGB Standard -o lk_oiio.exr
idiff -fail 1e-6 -a lk.exr lk_oiio.exr >/dev/null && pass "looks=Brighten == oiiotool --ociolook" ||
  fail "looks: $(idiff -a lk.exr lk_oiio.exr)"
idiff -fail 1e-3 -a lk.exr nolk.exr >/dev/null && fail "looks=Brighten changed nothing" ||
  pass "looks=Brighten changes the image"
# blanks around look names are dropped, and a look undone by its inverse leaves the plain view
run_ok c.exr --ociodisplay:config=looks.ocio:looks="Brighten, -Brighten" -o lk2.exr
idiff -fail 1e-5 -a lk2.exr nolk.exr >/dev/null && pass "looks 'Brighten, -Brighten' cancel" ||
  fail "looks with blanks: $(idiff -a lk2.exr nolk.exr)"
finish
