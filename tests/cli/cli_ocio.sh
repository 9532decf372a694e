# --ociodisplay with the shipped config (testdata/ocio/config.ocio): pixel values against the
# analytic sRGB OETF and the tone curves the LUTs encode; $OCIO overrides the default.
. "$(dirname "$0")/lib.sh"
unset OCIO
oiiotool --pattern constant:color=0.0,0.18,0.5 4x4 3 -o c1.exr
oiiotool --pattern constant:color=1.0,2.0,-0.3 4x4 3 -o c2.exr
oiiotool --pattern constant:color=0.002,0.04,8.0 4x4 3 -o c3.exr
# expected VIEW X: analytic display value of linear X
expected() {
  $PY - "$1" "$2" <<'PY'
import sys
view, x = sys.argv[1], float(sys.argv[2])
def s(v):
    v = min(max(v, 0.0), 1.0)
    return 12.92 * v if v <= 0.0031308 else 1.055 * v ** (1 / 2.4) - 0.055
def h(v):
    A, B, C, D, E, F = 0.15, 0.5, 0.1, 0.2, 0.02, 0.3
    return ((v * (A * v + C * B) + D * E) / (v * (A * v + B) + D * F)) - E / F
x = max(x, 0.0) if view != "Raw" else x
print({"Standard": s(x), "Reinhard": s(x / (1 + x)), "Filmic": s(h(2 * x) / h(11.2)),
       "Raw": x}[view])
PY
}
for view in Standard Reinhard Filmic Raw; do
  for img in c1:0.0,0.18,0.5 c2:1.0,2.0,-0.3 c3:0.002,0.04,8.0; do
    f=${img%%:*}
    vals=${img#*:}
    run_ok $f.exr --ociodisplay:display=sRGB:view=$view -o o_${f}_$view.exr
    read -r -a got <<<"$(oiiotool o_${f}_$view.exr --printstats | sed -n 's/.*Stats Avg: \(.*\) (float)/\1/p')"
    IFS=, read -r -a xs <<<"$vals"
    for k in 0 1 2; do
      want=$(expected $view ${xs[$k]})
      tol=1e-5
      [ $view = Reinhard ] || [ $view = Filmic ] && tol=2e-4 # 4096-entry LUT, linear interpolation
      near "${got[$k]}" "$want" $tol && pass "$view(${xs[$k]}) = ${got[$k]}" ||
        fail "$view(${xs[$k]}) = ${got[$k]}, expected $want"
    done
  done
done
# Default display/view are sRGB/Standard.
run_ok c1.exr --ociodisplay -o d.exr
run_ok d.exr o_c1_Standard.exr --l1 --json
grep -q '"l1": 0}' out.txt && pass "default view is Standard" || fail "default: $(cat out.txt)"
# $OCIO overrides the default config (a copy with views renamed must be used).
sed 's/name: Standard,/name: PlainCopy,/; s/\[Standard, /[PlainCopy, /' "$TD/ocio/config.ocio" >alt.ocio
cp "$TD"/ocio/*.spi1d .
OCIO=$PWD/alt.ocio run_ok c1.exr --ociodisplay:view=PlainCopy -o alt.exr
OCIO=$PWD/alt.ocio expect_fail "view 'Standard'" std.exr c1.exr --ociodisplay:view=Standard -o std.exr
# AOV images: only R,G,B are transformed.
run_ok "$NOISY" --ociodisplay:view=Filmic -o aov.png
oiiotool --info aov.png | grep -q "3 channel" && pass "AOV -> RGB png" || fail "$(oiiotool --info aov.png)"
finish
