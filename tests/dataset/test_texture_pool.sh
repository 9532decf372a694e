#!/bin/sh
# tools/texture_pool.py (the procedural bitmap pool of docs/training-log.md, session 44): a pure
# function of (seed, count), every file a square 8-bit RGB bitmap that tiles where its family
# says so, --exclude keeps a bitmap (and its shifts and flips) out, checked by brute force
# against np.roll instead of the tool's FFT; bad arguments are a clear error with nothing written.
# usage: test_texture_pool.sh TEXTURE_POOL_PY
set -u
S=$1
D=$(mktemp -d /tmp/kpcn_pool_XXXXXX)
trap 'rm -rf "$D"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
/usr/bin/python3 "$S" "$D/a" --count 30 --seed 3 >/dev/null || fail "write seed 3"
/usr/bin/python3 "$S" "$D/b" --count 30 --seed 3 >/dev/null || fail "write seed 3 again"
/usr/bin/python3 "$S" "$D/c" --count 30 --seed 4 >/dev/null || fail "write seed 4"
[ "$(ls "$D/a"/*.png | wc -l)" -eq 30 ] || fail "30 bitmaps expected"
for f in "$D"/a/*.png; do
  cmp -s "$f" "$D/b/$(basename "$f")" || fail "$(basename "$f") differs between runs"
done
same=0
for f in "$D"/a/*.png; do
  g=$(ls "$D"/c/"$(basename "$f" | cut -c1-9)"* 2>/dev/null) && cmp -s "$f" "$g" && same=$((same + 1))
done
[ $same -eq 0 ] || fail "seeds 3 and 4 made $same identical bitmaps"
# The first pool's bitmap 0 and a checker of the held-out recipe's kind, excluded: neither (nor
# any shift or flip of them) may come back, and the tool reports the nearest distance.
cp "$D/a/pool_0000_"*.png "$D/x0.png"
oiiotool --pattern checker:width=8:height=4:color1=0.55,0.2,0.12:color2=0.85,0.75,0.6 64x64 3 \
  -d uint8 -o "$D/x1.png" || fail "oiiotool checker"
/usr/bin/python3 "$S" "$D/e" --count 30 --seed 3 --exclude "$D/x0.png" "$D/x1.png" >"$D/e.log" ||
  fail "write with --exclude"
grep -q "excluded $D/x0.png: nearest pool bitmap" "$D/e.log" || fail "no nearest-bitmap report"
/usr/bin/python3 - "$D" <<'PY' || fail "exclusion / format check"
import json, os, sys
import numpy as np
import OpenImageIO as oiio
d = sys.argv[1]
def read(p):
    b = oiio.ImageBuf(p)
    s = b.spec()
    assert s.nchannels == 3 and s.format == oiio.UINT8 and s.width == s.height, p
    assert s.width in (32, 64, 128), p
    return b.get_pixels(oiio.FLOAT).astype(np.float64)
def to64(a):
    n = a.shape[0]
    if n >= 64:
        f = n // 64
        return a.reshape(64, f, 64, f, 3).mean(axis=(1, 3))
    return np.repeat(np.repeat(a, 64 // n, 0), 64 // n, 1)
def dist(a, b):  # brute force: every cyclic shift of every flip/rotation
    best = 1e9
    for k in range(4):
        for fl in (False, True):
            r = np.rot90(b, k)
            r = r[:, ::-1] if fl else r
            for dy in range(64):
                rr = np.roll(r, dy, 0)
                for dx in range(64):
                    best = min(best, np.sqrt(np.mean((a - np.roll(rr, dx, 1)) ** 2)))
    return best
m = json.load(open(os.path.join(d, "e", "pool.json")))
assert m["count"] == 30 and len(m["bitmaps"]) == 30
assert m["rejected_draws"] >= 1, "bitmap 0 itself must have been drawn and rejected"
x0, x1 = to64(read(os.path.join(d, "x0.png"))), to64(read(os.path.join(d, "x1.png")))
for e in m["bitmaps"]:
    a = to64(read(os.path.join(d, "e", e["file"])))
    assert dist(a, x0) >= 0.1, e["file"]
    if e["family"] == "checker" and e["params"]["cell"] == [8, 4]:
        c = np.array(e["params"]["colours"])
        ref = np.array([[0.55, 0.2, 0.12], [0.85, 0.75, 0.6]])
        assert min(np.abs(c - ref).max(), np.abs(c[::-1] - ref).max()) >= 0.15, e["file"]
# tileable families: the last column continues into the first as inside the bitmap
for e in json.load(open(os.path.join(d, "a", "pool.json")))["bitmaps"]:
    if e["family"] in ("bricks", "tiles", "stripes", "dots", "plaid"):
        a = read(os.path.join(d, "a", e["file"]))
        wrap = np.abs(a[:, 0] - a[:, -1]).mean()
        inner = max(np.abs(a[:, i] - a[:, i + 1]).mean() for i in range(a.shape[1] - 1))
        assert wrap <= inner + 1e-6, (e["file"], wrap, inner)
PY
# An excluded bitmap of any size is compared whole: box64 against an independent area average
# (each pixel repeated to the least common multiple of n and 64, then block means); before,
# sizes not a multiple of 64 were cropped to one (a 100x100 bitmap lost its last 36 rows).
/usr/bin/python3 - "$S" <<'PY' || fail "box64 on sizes other than 32, 64, 128"
import importlib.util, math, sys
import numpy as np
spec = importlib.util.spec_from_file_location("texture_pool", sys.argv[1])
tp = importlib.util.module_from_spec(spec)
spec.loader.exec_module(tp)
rng = np.random.default_rng(7)
for n in (16, 32, 48, 64, 96, 100, 128, 129, 200):
    img = rng.uniform(size=(n, n, 3))
    l = n * 64 // math.gcd(n, 64)
    big = np.repeat(np.repeat(img, l // n, 0), l // n, 1)
    ref = big.reshape(64, l // 64, 64, l // 64, 3).mean(axis=(1, 3))
    got = tp.box64(img)
    assert got.shape == (64, 64, 3) and np.abs(got - ref).max() < 1e-12, n
PY
# a folder holding an earlier pool is refused, and left as it was
/usr/bin/python3 "$S" "$D/a" --count 5 --seed 9 2>"$D/err0" && fail "existing pool folder accepted"
grep -q "already holds files" "$D/err0" || fail "existing folder: $(cat "$D/err0")"
[ "$(ls "$D/a"/*.png | wc -l)" -eq 30 ] || fail "existing folder changed"
# bad input: a clear error, a non-zero exit, no output directory
/usr/bin/python3 "$S" "$D/bad1" --exclude "$D/none.png" 2>"$D/err1" && fail "missing --exclude file accepted"
grep -q "none.png" "$D/err1" || fail "missing file not named: $(cat "$D/err1")"
/usr/bin/python3 "$S" "$D/bad2" --count 0 2>"$D/err2" && fail "--count 0 accepted"
grep -q "count" "$D/err2" || fail "--count error unclear"
[ ! -e "$D/bad1" ] && [ ! -e "$D/bad2" ] || fail "output written on bad input"
# --from DIR: photographs. Of nine candidates, three are eligible (a wide image is cut to its
# centre square); an RGBA cut-out, a 20-pixel image, a 40x200 strip, a flat and a black one
# are skipped, and a copy of an excluded bitmap is rejected. Each bitmap is checked against an
# independent area average of its source's centre square; too few eligible images is an error
# that writes nothing.
mkdir -p "$D/src/sub"
/usr/bin/python3 - "$D" <<'PY' || fail "write --from sources"
import sys
import numpy as np
import OpenImageIO as oiio
d = sys.argv[1]
rng = np.random.default_rng(11)
def write(name, a):
    h, w, c = a.shape
    o = oiio.ImageBuf(oiio.ImageSpec(w, h, c, oiio.UINT8))
    o.set_pixels(oiio.ROI(0, w, 0, h, 0, 1, 0, c), a.astype(np.float32))
    assert o.write(d + "/src/" + name), name
write("good_a.png", rng.uniform(0.2, 0.8, (96, 144, 3)))
write("sub/good_b.tga", rng.uniform(0.1, 0.6, (64, 64, 3)))
write("good_c.png", rng.uniform(0.3, 0.9, (40, 40, 1)))
cut = np.concatenate([rng.uniform(0.2, 0.8, (64, 64, 3)), np.ones((64, 64, 1))], 2)
cut[:8, :8, 3] = 0
write("cutout.png", cut)
write("small.png", rng.uniform(0.2, 0.8, (20, 20, 3)))
write("strip.png", rng.uniform(0.2, 0.8, (40, 200, 3)))
write("flat.png", np.full((64, 64, 3), 0.5))
write("black.png", np.zeros((64, 64, 3)))
b = oiio.ImageBuf(d + "/x0.png")
write("sub/copy.png", b.get_pixels(oiio.FLOAT).astype(np.float64))
PY
/usr/bin/python3 "$S" "$D/p1" --count 3 --seed 5 --from "$D/src" --exclude "$D/x0.png" >/dev/null ||
  fail "--from"
/usr/bin/python3 "$S" "$D/p2" --count 3 --seed 5 --from "$D/src" --exclude "$D/x0.png" >/dev/null ||
  fail "--from again"
for f in "$D"/p1/*.png; do
  cmp -s "$f" "$D/p2/$(basename "$f")" || fail "--from: $(basename "$f") differs between runs"
done
/usr/bin/python3 - "$D" <<'PY' || fail "--from bitmaps"
import json, math, sys
import numpy as np
import OpenImageIO as oiio
d = sys.argv[1]
m = json.load(open(d + "/p1/pool.json"))
assert m["skipped"] == {"alpha": 1, "small": 1, "strip": 1, "flat": 1, "dark or bright": 1}, m
assert m["rejected_draws"] == 1, m
srcs = sorted(e["params"]["source"] for e in m["bitmaps"])
assert srcs == ["good_a.png", "good_c.png", "sub/good_b.tga"], srcs
for e in m["bitmaps"]:
    assert e["family"] == "photo" and e["file"].endswith("_photo.png"), e
    src = oiio.ImageBuf(d + "/src/" + e["params"]["source"]).get_pixels(oiio.FLOAT)
    src = np.asarray(src, np.float64)
    if src.shape[2] == 1:
        src = np.repeat(src, 3, 2)
    h, w = src.shape[:2]
    n = min(h, w)
    sq = src[(h - n) // 2:(h - n) // 2 + n, (w - n) // 2:(w - n) // 2 + n, :3]
    got = oiio.ImageBuf(d + "/p1/" + e["file"])
    s = got.spec()
    m_ = s.width
    assert s.nchannels == 3 and s.width == s.height and m_ in (32, 64, 128) and m_ <= n, e
    l = n * m_ // math.gcd(n, m_)
    big = np.repeat(np.repeat(sq, l // n, 0), l // n, 1)
    ref = big.reshape(m_, l // m_, m_, l // m_, 3).mean(axis=(1, 3))
    px = got.get_pixels(oiio.FLOAT).astype(np.float64)
    assert np.abs(px - ref).max() <= 0.5 / 255 + 1e-6, (e["file"], np.abs(px - ref).max())
PY
/usr/bin/python3 "$S" "$D/p3" --count 4 --from "$D/src" --exclude "$D/x0.png" 2>"$D/err3" &&
  fail "--from with too few eligible images accepted"
grep -q "only 3 of the images are eligible" "$D/err3" || fail "--from shortage: $(cat "$D/err3")"
/usr/bin/python3 "$S" "$D/p4" --count 1 --from "$D/none" 2>"$D/err4" && fail "missing --from accepted"
grep -q "none' is not a folder" "$D/err4" || fail "missing --from: $(cat "$D/err4")"
[ ! -e "$D/p3" ] && [ ! -e "$D/p4" ] || fail "--from: output written on bad input"
echo "test_texture_pool: all passed"
