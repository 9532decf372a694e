#!/usr/bin/python3
"""A pool of procedural albedo bitmaps for kpcn-dataset plan --texture-dir (a broad pool of
surface patterns, so that a bitmap in an unseen scene is close to something learnt).

usage: tools/texture_pool.py OUT_DIR [--count N] [--seed S] [--from DIR] [--exclude PNG ...]

Writes N (default 256) 8-bit RGB PNGs, OUT_DIR/pool_NNNN_FAMILY.png, drawn from twelve
families (running-bond bricks, noisy rectangle checkers, tiles with grout, stripes, dots,
coloured fractal noise, marble, wood, Voronoi flagstones, four-corner gradients, plaid,
random rectangles) at 32, 64 or 128 pixels square, colours drawn in HSV with albedos 0.03..0.9.
The same seed and count give the same files byte for byte (numpy's PCG64, one generator per
bitmap seeded with (S, index)). A manifest OUT_DIR/pool.json lists every file, its family and
its parameters.

--from DIR: photographs instead of procedural families (session 63: a game's surface textures,
Debian's openarena-081-textures). Every .jpg/.jpeg/.png/.tga/.tif under DIR, in sorted order, is
a candidate; the seed shuffles them and the first COUNT that pass are taken, each at most once.
A candidate is cut to its centre square and area-averaged to 32, 64 or 128 pixels (drawn, at
most its own size). It is skipped when its shorter side is under 32 pixels, its sides differ by
more than 4x (trims), it has an alpha channel that is not opaque everywhere (decals, cut-outs),
its mean is outside 0.03..0.9 or its standard deviation under 0.02 (flat), or it is excluded.
Family "photo"; pool.json records each bitmap's source path. Fewer eligible files than COUNT
is an error naming how many there were.

--exclude PNG: the pool must not contain these bitmaps (the held-out scenes' own). A draw is
rejected and drawn again when, after both are resampled to 64x64 (box filter), its RMS
difference to an excluded bitmap under any of the 64x64 cyclic shifts and 8 flips/rotations is
below 0.1, or when it is of an excluded bitmap's kind with nearly its parameters: a checker
with the same cell size whose two colours are within 0.15 of an excluded checker's, or a
gradient whose corners are within 0.15 of an excluded gradient's under some symmetry.
Prints, per excluded file, the nearest pool bitmap and its distance. OUT_DIR must be new or
empty (an earlier pool's bitmaps would stay beside the new ones).
"""
import argparse
import colorsys
import json
import os
import sys

import numpy as np
import OpenImageIO as oiio

FAMILIES = ("bricks", "checker", "tiles", "stripes", "dots", "noise", "marble", "wood",
            "voronoi", "gradient", "plaid", "rects")


def colour(rng, vmin=0.05, vmax=0.9, smax=0.8):
    h, s, v = rng.uniform(), rng.uniform(0, smax), rng.uniform(vmin, vmax)
    return np.array(colorsys.hsv_to_rgb(h, s, v), np.float64)


def near(c, rng, amount):
    """A colour close to c (a per-element tint)."""
    return np.clip(c * np.exp(rng.normal(0, amount, 3)), 0.02, 0.95)


def value_noise(n, period, rng):
    """Tileable smooth value noise on an n x n grid, `period` lattice cells across, in [0, 1]."""
    lat = rng.uniform(size=(period, period))
    t = np.arange(n) * period / n
    i = np.floor(t).astype(int)
    f = t - i
    f = f * f * (3 - 2 * f)
    i0, i1 = i % period, (i + 1) % period
    a = lat[np.ix_(i0, i0)] * (1 - f)[None, :] + lat[np.ix_(i0, i1)] * f[None, :]
    b = lat[np.ix_(i1, i0)] * (1 - f)[None, :] + lat[np.ix_(i1, i1)] * f[None, :]
    return a * (1 - f)[:, None] + b * f[:, None]


def fbm(n, period, rng, octaves=4):
    out = np.zeros((n, n))
    w = 0.5
    for o in range(octaves):
        p = min(period * 2**o, n)
        out += w * value_noise(n, p, rng)
        w /= 2
    return out / (1 - 0.5**octaves)


def lerp(c0, c1, t):
    return c0[None, None, :] * (1 - t[..., None]) + c1[None, None, :] * t[..., None]


def grid(n):
    y, x = np.mgrid[0:n, 0:n]
    return x, y


def divisor(rng, n, choices):
    """A cell size from choices that divides n (so the bitmap tiles)."""
    ok = [c for c in choices if n % c == 0]
    return int(rng.choice(ok))


def gen_bricks(rng, n):
    x, y = grid(n)
    bh = divisor(rng, n, (4, 8, 16))
    bw = divisor(rng, n, tuple(c for c in (8, 16, 32) if c >= bh))
    m = int(rng.integers(1, 3))
    row = y // bh
    xs = (x + (row % 2) * (bw // 2)) % n
    col = xs // bw
    mortar = ((y % bh) < m) | ((xs % bw) < m)
    base, mc = colour(rng, 0.1, 0.7), colour(rng, 0.2, 0.9, 0.3)
    nb = (n // bw) * (n // bh)
    tint = np.exp(rng.normal(0, 0.15, (nb, 3)))
    idx = (row * (n // bw) + col) % nb
    img = np.clip(base[None, None, :] * tint[idx], 0, 0.95)
    img = img * (1 + rng.uniform(0, 0.3) * (fbm(n, 8, rng) - 0.5))[..., None]
    img[mortar] = mc
    return img, {"brick": [bw, bh], "mortar": m}


def gen_checker(rng, n):
    x, y = grid(n)
    cw = divisor(rng, n, (2, 4, 8, 16, 32))
    ch = divisor(rng, n, (2, 4, 8, 16, 32))
    c0, c1 = colour(rng), colour(rng)
    amp = float(rng.uniform(0, 0.2))
    t = (((x // cw) + (y // ch)) % 2).astype(np.float64)
    img = lerp(c0, c1, t) + amp * rng.uniform(size=(n, n))[..., None]
    return img, {"cell": [cw, ch], "colours": [c0.tolist(), c1.tolist()], "noise": amp}


def gen_tiles(rng, n):
    x, y = grid(n)
    s = divisor(rng, n, (8, 16, 32))
    g = int(rng.integers(1, 3))
    base, gc = colour(rng, 0.3, 0.9), colour(rng, 0.1, 0.6, 0.3)
    k = n // s
    tint = rng.normal(0, 0.08, (k * k, 1))
    idx = (y // s) * k + (x // s)
    img = np.clip(base[None, None, :] + tint[idx], 0.02, 0.95)
    img[((x % s) < g) | ((y % s) < g)] = gc
    return img, {"tile": s, "grout": g}


def gen_stripes(rng, n):
    x, y = grid(n)
    period = divisor(rng, n, (4, 8, 16, 32, 64))
    slope = int(rng.integers(0, 3))  # 0: straight, 1 or 2: diagonal, still tileable
    cols = [colour(rng) for _ in range(int(rng.integers(2, 4)))]
    widths = rng.dirichlet(np.ones(len(cols)))
    edges = np.cumsum(widths) * period
    s = (x + slope * y) % period
    img = np.zeros((n, n, 3))
    lo = 0.0
    for c, hi in zip(cols, edges):
        img[(s >= lo) & (s < hi + 1e-9)] = c
        lo = hi
    return img, {"period": period, "slope": slope, "stripes": len(cols)}


def gen_dots(rng, n):
    x, y = grid(n)
    p = divisor(rng, n, (8, 16, 32))
    r = rng.uniform(0.15, 0.45) * p
    u, v = (x % p) - p / 2 + 0.5, ((y + (y // p % 2) * 0) % p) - p / 2 + 0.5
    bg, fg = colour(rng), colour(rng)
    img = np.where((u * u + v * v < r * r)[..., None], fg[None, None, :], bg[None, None, :])
    return img, {"period": p, "radius": float(r)}


def gen_noise(rng, n):
    period = int(rng.choice([2, 4, 8, 16]))
    c0, c1 = colour(rng), colour(rng)
    t = fbm(n, period, rng, int(rng.integers(2, 6)))
    t = np.clip((t - 0.5) * rng.uniform(1, 3) + 0.5, 0, 1)
    return lerp(c0, c1, t), {"period": period}


def gen_marble(rng, n):
    x, y = grid(n)
    k = int(rng.integers(1, 5))
    t = np.sin(2 * np.pi * k * (x + y * int(rng.integers(0, 2))) / n + rng.uniform(3, 8) * fbm(n, 4, rng))
    t = np.abs(t) ** rng.uniform(0.2, 0.6)
    c0, c1 = colour(rng, 0.05, 0.5), colour(rng, 0.5, 0.9, 0.2)
    return lerp(c0, c1, t), {"bands": k}


def gen_wood(rng, n):
    x, _ = grid(n)
    rings = int(rng.integers(3, 12))
    r = 2 * np.pi * rings * x / n + rng.uniform(2, 10) * fbm(n, 4, rng)
    t = 0.5 + 0.5 * np.sin(r)
    c0 = colour(rng, 0.15, 0.5, 0.9)
    c1 = near(c0, rng, 0.3) * 1.6
    return lerp(c0, np.clip(c1, 0, 0.95), t), {"rings": rings}


def gen_voronoi(rng, n):
    x, y = grid(n)
    k = int(rng.integers(6, 40))
    pts = rng.uniform(0, n, (k, 2))
    d = []
    for px, py in pts:  # distances on the torus so the bitmap tiles
        dx = np.abs(x - px)
        dy = np.abs(y - py)
        d.append(np.hypot(np.minimum(dx, n - dx), np.minimum(dy, n - dy)))
    d = np.stack(d)
    order = np.argsort(d, axis=0)
    d1 = np.take_along_axis(d, order[:1], 0)[0]
    d2 = np.take_along_axis(d, order[1:2], 0)[0]
    base = colour(rng, 0.2, 0.85, 0.5)
    tint = np.exp(rng.normal(0, 0.2, (k, 3)))
    img = np.clip(base[None, None, :] * tint[order[0]], 0, 0.95)
    crack = float(rng.uniform(0.5, 2.0))
    img[(d2 - d1) < crack] = colour(rng, 0.03, 0.3, 0.3)
    return img, {"cells": k, "crack": crack}


def gen_gradient(rng, n):
    c = [colour(rng) for _ in range(4)]
    t = (np.arange(n) + 0.5) / n
    top = lerp(c[0], c[1], np.broadcast_to(t[None, :], (1, n)))[0]
    bot = lerp(c[2], c[3], np.broadcast_to(t[None, :], (1, n)))[0]
    img = top[None, :, :] * (1 - t)[:, None, None] + bot[None, :, :] * t[:, None, None]
    return img, {"corners": [ci.tolist() for ci in c]}


def gen_plaid(rng, n):
    x, y = grid(n)
    p = divisor(rng, n, (8, 16, 32))
    w = rng.uniform(0.2, 0.5) * p
    bg, c1, c2 = colour(rng), colour(rng), colour(rng)
    sx, sy = (x % p) < w, (y % p) < w
    img = np.broadcast_to(bg, (n, n, 3)).copy()
    img[sx] = 0.5 * img[sx] + 0.5 * c1
    img[sy] = 0.5 * img[sy] + 0.5 * c2
    return img, {"period": p, "width": float(w)}


def gen_rects(rng, n):
    img = np.broadcast_to(colour(rng), (n, n, 3)).copy()
    k = int(rng.integers(4, 30))
    for _ in range(k):
        x0, y0 = rng.integers(0, n, 2)
        w, h = rng.integers(2, max(3, n // 3), 2)
        ys, xs = (np.arange(y0, y0 + h) % n), (np.arange(x0, x0 + w) % n)
        img[np.ix_(ys, xs)] = colour(rng)
    return img, {"rects": k}


GEN = {f: globals()["gen_" + f] for f in FAMILIES}


def area_matrix(n, m=64):
    """A (m, n) matrix whose rows average an n-pixel row onto m cells by covered length."""
    a = np.zeros((m, n))
    for i in range(m):
        lo, hi = i * n / m, (i + 1) * n / m
        for j in range(int(np.floor(lo)), min(n, int(np.ceil(hi)))):
            a[i, j] = min(hi, j + 1) - max(lo, j)
    return a / a.sum(axis=1, keepdims=True)


def area_resample(img, m):
    """A square bitmap averaged onto m x m cells by covered area (rows, then columns: two
    matrix products, where one einsum over both would loop over every pixel pair)."""
    a = area_matrix(img.shape[0], m)
    rows = np.tensordot(a, img, axes=(1, 0))
    return np.tensordot(a, rows, axes=(1, 1)).transpose(1, 0, 2)


def box64(img):
    """Resample a square bitmap to 64x64 (box filter down, nearest up). Sizes that are not a
    multiple or a divisor of 64 (an excluded scene bitmap can be any size) are averaged by
    covered area, so the whole bitmap counts (cropping to a multiple dropped its last rows)."""
    n = img.shape[0]
    if n >= 64 and n % 64 == 0:
        f = n // 64
        return img.reshape(64, f, 64, f, 3).mean(axis=(1, 3))
    if n < 64 and 64 % n == 0:
        return np.repeat(np.repeat(img, 64 // n, 0), 64 // n, 1)
    return area_resample(img, 64)


def symmetries(img):
    for k in range(4):
        r = np.rot90(img, k)
        yield r
        yield r[:, ::-1]


def shift_rms(a, b):
    """The least RMS difference between a and b over all cyclic shifts (via the FFT)."""
    fa, fb = np.fft.rfft2(a, axes=(0, 1)), np.fft.rfft2(b, axes=(0, 1))
    corr = np.fft.irfft2(fa * np.conj(fb), s=a.shape[:2], axes=(0, 1)).sum(axis=2)
    ss = (a * a).sum() + (b * b).sum() - 2 * corr.max()
    return float(np.sqrt(max(ss, 0) / a.size))


def distance(img64, excl64):
    return min(shift_rms(img64, s) for s in symmetries(excl64))


def read_png(path):
    inp = oiio.ImageInput.open(path)
    if not inp:
        sys.exit("texture_pool.py: cannot read '%s': %s" % (path, oiio.geterror()))
    px = inp.read_image(0, 0, 0, 3, "float")
    inp.close()
    if px is None or px.shape[0] != px.shape[1]:
        sys.exit("texture_pool.py: '%s' is not a square RGB bitmap" % path)
    return np.asarray(px, np.float64)


PHOTO_EXT = (".jpg", ".jpeg", ".png", ".tga", ".tif", ".tiff")


def photo_candidates(root):
    """Every image file under root, as sorted paths relative to it (the order the seed shuffles)."""
    found = []
    for d, dirs, files in os.walk(root):
        dirs.sort()
        for f in files:
            if f.lower().endswith(PHOTO_EXT):
                found.append(os.path.relpath(os.path.join(d, f), root))
    return sorted(found)


def read_photo(path, rng):
    """The candidate as a square RGB float bitmap of 32, 64 or 128 pixels, or (None, why)."""
    inp = oiio.ImageInput.open(path)
    if not inp:
        oiio.geterror()
        return None, "unreadable"
    spec = inp.spec()
    px = inp.read_image(0, 0, 0, spec.nchannels, "float")
    inp.close()
    if px is None:
        return None, "unreadable"
    px = np.asarray(px, np.float64)
    h, w = px.shape[:2]
    if min(h, w) < 32:
        return None, "small"
    if max(h, w) > 4 * min(h, w):
        return None, "strip"
    c = px.shape[2]
    if c in (2, 4) and px[:, :, c - 1].min() < 0.99:
        return None, "alpha"
    rgb = np.repeat(px[:, :, :1], 3, 2) if c < 3 else px[:, :, :3]
    n = min(h, w)
    y0, x0 = (h - n) // 2, (w - n) // 2
    sq = rgb[y0:y0 + n, x0:x0 + n]
    size = int(rng.choice([s for s in (32, 64, 128) if s <= n]))
    img = np.clip(area_resample(sq, size), 0, 1)
    if not 0.03 <= img.mean() <= 0.9:
        return None, "dark or bright"
    if img.std() < 0.02:
        return None, "flat"
    return img, None


def excluded_kind(fam, params, excl):
    """A checker or gradient with nearly the parameters of an excluded one."""
    if fam == "checker" and excl.get("cell") == params["cell"]:
        a = np.array(params["colours"])
        b = np.array(excl["colours"])
        return np.abs(a - b).max() < 0.15 or np.abs(a[::-1] - b).max() < 0.15
    if fam == "gradient" and "corners" in excl:
        a = np.array(params["corners"]).reshape(2, 2, 3)
        b = np.array(excl["corners"]).reshape(2, 2, 3)
        return any(np.abs(s - b).max() < 0.15 for s in symmetries(a))
    return False


def infer_params(img):
    """The checker or gradient parameters an excluded bitmap would have, when it is one."""
    n = img.shape[0]
    # A gradient: its corners (bilinear images are fitted exactly by them).
    c = [img[0, 0], img[0, -1], img[-1, 0], img[-1, -1]]
    out = {"corners": [ci.tolist() for ci in c]}
    # A two-colour checker with noise: the two cluster means and the cell size of the pattern.
    lum = img.mean(axis=2)
    hi = lum > np.median(lum)
    for cw in (2, 4, 8, 16, 32):
        for ch in (2, 4, 8, 16, 32):
            if n % cw or n % ch:
                continue
            x, y = grid(n)
            t = (((x // cw) + (y // ch)) % 2).astype(bool)
            if (t == hi).mean() > 0.95 or (t != hi).mean() > 0.95:
                lo_c, hi_c = img[~hi].mean(axis=0), img[hi].mean(axis=0)
                out["cell"] = [cw, ch]
                out["colours"] = [lo_c.tolist(), hi_c.tolist()]
                return out
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out")
    ap.add_argument("--count", type=int, default=256)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--exclude", nargs="*", default=[])
    ap.add_argument("--from", dest="src", metavar="DIR")
    a = ap.parse_args()
    if not 1 <= a.count <= 100000:
        sys.exit("texture_pool.py: --count must be 1..100000")
    excl = []
    for p in a.exclude:
        img = read_png(p)
        excl.append((p, box64(img), infer_params(img)))
    if os.path.isdir(a.out) and os.listdir(a.out):
        # bitmaps of an earlier pool would stay beside the new one and be drawn from by
        # kpcn-dataset plan --texture-dir, while pool.json lists only the new ones
        sys.exit("texture_pool.py: '%s' already holds files (an earlier pool?); write the pool "
                 "to a new or empty folder" % a.out)
    if os.path.exists(a.out) and not os.path.isdir(a.out):
        sys.exit("texture_pool.py: '%s' exists and is not a folder" % a.out)
    if a.src and not os.path.isdir(a.src):
        sys.exit("texture_pool.py: --from '%s' is not a folder" % a.src)
    manifest = []
    nearest = {p: (1e9, None) for p, _, _ in excl}
    rejected = 0
    skipped = {}

    def is_excluded(fam, params, img):
        ds = [(distance(box64(img), e64), p) for p, e64, _ in excl]
        bad = any(d < 0.1 for d, _ in ds) or any(excluded_kind(fam, params, ep)
                                                 for _, _, ep in excl)
        return bad, ds

    def procedural():
        nonlocal rejected
        for i in range(a.count):
            rng = np.random.default_rng([a.seed, i])
            while True:
                fam = FAMILIES[int(rng.integers(len(FAMILIES)))]
                n = int(rng.choice([32, 64, 128]))
                img, params = GEN[fam](rng, n)
                img = np.clip(img, 0, 1)
                bad, ds = is_excluded(fam, params, img)
                if not bad:
                    yield fam, img, params, ds
                    break
                rejected += 1

    def photographs():
        nonlocal rejected
        cand = photo_candidates(a.src)
        order = np.random.default_rng([a.seed]).permutation(len(cand))
        for k in order:
            rng = np.random.default_rng([a.seed, int(k)])
            img, why = read_photo(os.path.join(a.src, cand[k]), rng)
            if img is None:
                skipped[why] = skipped.get(why, 0) + 1
                continue
            params = {"source": cand[k]}
            bad, ds = is_excluded("photo", params, img)
            if bad:
                rejected += 1
                continue
            yield "photo", img, params, ds

    # Everything is drawn before anything is written: too few eligible photographs is an error
    # that leaves OUT_DIR as it was.
    drawn = []
    for draw in (photographs() if a.src else procedural()):
        drawn.append(draw)
        if len(drawn) == a.count:
            break
    if len(drawn) < a.count:
        sys.exit("texture_pool.py: --from '%s': only %d of the images are eligible (%s; %d "
                 "excluded), --count asks for %d" % (a.src, len(drawn), ", ".join(
                     "%d %s" % (v, k) for k, v in sorted(skipped.items())) or "none skipped",
                     rejected, a.count))
    os.makedirs(a.out, exist_ok=True)
    for i, (fam, img, params, ds) in enumerate(drawn):
        name = "pool_%04d_%s.png" % (i, fam)
        for d, p in ds:
            if d < nearest[p][0]:
                nearest[p] = (d, name)
        n = img.shape[0]
        out = oiio.ImageOutput.create(os.path.join(a.out, name))
        spec = oiio.ImageSpec(n, n, 3, "uint8")
        if not out or not out.open(os.path.join(a.out, name), spec):
            sys.exit("texture_pool.py: cannot write '%s': %s" % (name, oiio.geterror()))
        out.write_image(np.round(img * 255).astype(np.uint8))
        out.close()
        manifest.append({"file": name, "family": fam, "size": n, "params": params})
    with open(os.path.join(a.out, "pool.json"), "w") as f:
        json.dump({"seed": a.seed, "count": a.count, "from": a.src, "excluded": a.exclude,
                   "rejected_draws": rejected, "skipped": skipped, "bitmaps": manifest}, f,
                  indent=1)
    fams = {}
    for m in manifest:
        fams[m["family"]] = fams.get(m["family"], 0) + 1
    print("texture_pool.py: %d bitmaps in %s (%s); %d draws rejected" %
          (a.count, a.out, ", ".join("%s %d" % kv for kv in sorted(fams.items())), rejected))
    for p, (d, name) in nearest.items():
        print("  excluded %s: nearest pool bitmap %s, RMS %.3f" % (p, name, d))


if __name__ == "__main__":
    main()
