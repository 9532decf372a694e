#!/usr/bin/python3
"""What the KPCN does at a few pixels: their predicted kernels, drawn.

usage: tools/show_kernels.py KERNELS.exr X,Y [X,Y ...] [-o OUT.png] [--scale S] [--json]

KERNELS.exr is a `kpcntool AOV.exr --kernels:model=M.safetensors[:branch=...] -o KERNELS.exr`
file (docs/denoiser.md, "Predicted kernels"). For each pixel (x, y) (image coordinates of the
file's data window, 0,0 at its first pixel) it computes
  - the kernel: the K x K softmax weights the network predicted there;
  - the footprint: the weight every input pixel gets in that pixel's result after all
    kpcn:kernelPasses passes (each pass filters the previous one with every pixel's own kernel,
    reads clamped at the image border), a (P(K-1)+1)^2 window;
and prints per pixel (one JSON object with --json) the footprint's sum (1), its spread (the
weighted rms distance from the pixel, in pixels), the share of the weight on the pixel itself
and the branch result there (the footprint applied to pre.R/G/B, the preprocessed colour).
-o writes a PNG: per pixel, one row of the kernel and the footprint (magnified, white = the
largest weight), after a strip of the preprocessed colour (log-scaled grey) with the pixels
marked."""
import argparse
import json
import sys

import kpcn_tools

import numpy as np
import OpenImageIO as oiio


def fail(msg):
    sys.exit("show_kernels: " + msg)


def load(path):
    buf = oiio.ImageBuf(path)
    pix = buf.get_pixels(oiio.FLOAT)
    if pix is None:
        fail("%s: %s" % (path, buf.geterror()))
    spec = buf.spec()
    K, P = spec.getattribute("kpcn:kernelSize"), spec.getattribute("kpcn:kernelPasses")
    if not isinstance(K, int) or not isinstance(P, int) or K < 1 or P < 1:
        fail("%s is no kpcntool --kernels file (kpcn:kernelSize %r, kpcn:kernelPasses %r)" %
             (path, K, P))
    names = list(spec.channelnames)
    want = ["pre.R", "pre.G", "pre.B"] + ["kernel.%03d" % t for t in range(K * K)]
    missing = [n for n in want if n not in names]
    if missing:
        fail("%s lacks channel %s" % (path, missing[0]))
    w = np.stack([pix[..., names.index("kernel.%03d" % t)] for t in range(K * K)]).astype(np.float64)
    pre = np.stack([pix[..., names.index("pre." + c)] for c in "RGB"]).astype(np.float64)
    return K, P, w, pre, spec.getattribute("kpcn:branch")


def footprint(w, K, P, x, y):
    """Weights of every input pixel in pixel (x, y)'s result after P passes: the result's
    weight map pulled back through each pass (clamped reads land on the border pixel)."""
    _, H, W = w.shape
    r = K // 2
    e = np.zeros((H, W))
    e[y, x] = 1.0
    for _ in range(P):
        back = np.zeros_like(e)
        for qy, qx in zip(*np.nonzero(e)):
            for t in range(K * K):
                sy = min(max(qy + t // K - r, 0), H - 1)
                sx = min(max(qx + t % K - r, 0), W - 1)
                back[sy, sx] += e[qy, qx] * w[t, qy, qx]
        e = back
    R = P * r
    win = np.zeros((2 * R + 1, 2 * R + 1))
    for sy, sx in zip(*np.nonzero(e)):
        # a border pixel collects the clamped reads: shown where it lies, inside the window
        win[sy - y + R, sx - x + R] += e[sy, sx]
    return e, win


def magnify(img, s):
    return np.kron(img, np.ones((s, s)))


def main():
    ap = kpcn_tools.parser(__doc__)
    ap.add_argument("kernels")
    ap.add_argument("pixels", nargs="+")
    ap.add_argument("-o", dest="out")
    ap.add_argument("--scale", type=int, default=8)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    if not 1 <= a.scale <= 64:
        fail("--scale must be in [1, 64]")
    K, P, w, pre, branch = load(a.kernels)
    H, W = pre.shape[1:]
    pts = []
    for p in a.pixels:
        try:
            x, y = (int(v) for v in p.split(","))
        except ValueError:
            fail("pixel '%s' is not X,Y" % p)
        if not (0 <= x < W and 0 <= y < H):
            fail("pixel %d,%d lies outside the %dx%d image" % (x, y, W, H))
        pts.append((x, y))
    rows, report = [], []
    for x, y in pts:
        e, win = footprint(w, K, P, x, y)
        yy, xx = np.mgrid[0:H, 0:W]
        spread = float(np.sqrt((e * ((yy - y) ** 2 + (xx - x) ** 2)).sum()))
        result = [float((e * pre[c]).sum()) for c in range(3)]
        r = {"x": x, "y": y, "branch": branch, "kernel_size": K, "passes": P,
             "footprint_sum": float(e.sum()), "spread_px": spread,
             "self_weight": float(e[y, x]), "result": result}
        report.append(r)
        if not a.json:
            print("%d,%d: footprint sum %.6f, spread %.2f px, own weight %.3f, result %s" %
                  (x, y, r["footprint_sum"], spread, r["self_weight"],
                   " ".join("%.5g" % v for v in result)))
        kern = w[:, y, x].reshape(K, K)
        rows.append((kern, win))
    if a.json:
        print(json.dumps(report))
    if not a.out:
        return
    s = a.scale
    R = P * (K // 2)
    side = (2 * R + 1) * s
    tiles = []
    for kern, win in rows:
        k = magnify(kern / max(kern.max(), 1e-30), s * (2 * R + 1) // K if K > 1 else s)
        f = magnify(win / max(win.max(), 1e-30), s)
        kk = np.zeros((side, side))
        kk[:k.shape[0], :k.shape[1]] = k
        tiles.append(np.concatenate([kk, np.full((side, 4), 0.5), f], 1))
    grid = np.concatenate([np.concatenate([t, np.full((4, t.shape[1]), 0.5)], 0) for t in tiles], 0)
    lum = np.log1p(np.maximum(pre.mean(0), 0))
    lum = lum / max(lum.max(), 1e-30)
    strip = np.stack([lum] * 3, -1)
    for x, y in pts:
        strip[max(y - 1, 0):y + 2, max(x - 1, 0):x + 2] = [1.0, 0.1, 0.1]
    hs = grid.shape[0]
    zoom = max(1, hs // H)
    strip = np.stack([np.kron(strip[..., c], np.ones((zoom, zoom))) for c in range(3)], -1)
    h = max(hs, strip.shape[0])
    canvas = np.zeros((h, strip.shape[1] + 4 + grid.shape[1], 3))
    canvas[:strip.shape[0], :strip.shape[1]] = strip
    canvas[:hs, strip.shape[1] + 4:] = np.stack([grid] * 3, -1)
    out = oiio.ImageBuf(oiio.ImageSpec(canvas.shape[1], canvas.shape[0], 3, oiio.UINT8))
    out.set_pixels(oiio.ROI(), canvas.astype(np.float32))
    if not out.write(a.out):
        fail("cannot write %s: %s" % (a.out, out.geterror()))


if __name__ == "__main__":
    main()
