#!/usr/bin/python3
"""Splits a denoiser's error into residual variance and the rest (bias, plus the reference's
own noise), from several results of independent renders of one scene.

usage: tools/variance_split.py REF.exr OUT1.exr OUT2.exr [OUT3.exr ...] [--top 0.05]

OUTi are the same method's results on renders that differ only in their seed (for example
`kpcn-render --seed i` then `kpcntool --denoise:...`). All images are compared on R, G, B
with the relMSE weight 1 / (ref^2 + 0.01) (kpcntool --relmse). Prints one JSON object:

  relmse        mean over the OUTi of their relMSE against REF
  variance      the unbiased per-pixel sample variance across the OUTi, weighted and averaged:
                the part a single result has because its input was noisy
  rest          relmse - variance: squared bias plus the reference's own noise (each result's
                expected relMSE = variance + bias^2 + reference noise, with independent seeds)
  variance_share  variance / relmse
  top_share     the share of the variance in the worst --top fraction of pixels (default 5 %)

A large variance share says a wider averaging footprint can still help; a large rest says
the result is off in the mean (blur, lost detail) or the reference is too noisy."""
import argparse
import json
import sys

import numpy as np
import OpenImageIO as oiio


def fail(msg):
    print("variance_split.py: " + msg, file=sys.stderr)
    sys.exit(1)


def read_rgb(path):
    buf = oiio.ImageBuf(path)
    if buf.has_error:
        fail("%s: %s" % (path, buf.geterror()))
    names = list(buf.spec().channelnames)
    for c in ("R", "G", "B"):
        if c not in names:
            fail("%s: no channel %s (channels: %s)" % (path, c, ", ".join(names)))
    px = buf.get_pixels(oiio.FLOAT)
    if px is None:
        fail("%s: cannot read the pixels: %s" % (path, buf.geterror()))
    rgb = np.stack([px[..., names.index(c)] for c in ("R", "G", "B")], -1).astype(np.float64)
    if not np.all(np.isfinite(rgb)):
        fail("%s: %d non-finite values in R, G, B" % (path, int(np.sum(~np.isfinite(rgb)))))
    return rgb


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("ref")
    ap.add_argument("outs", nargs="+")
    ap.add_argument("--top", type=float, default=0.05)
    a = ap.parse_args()
    if len(a.outs) < 2:
        fail("needs at least two results of independent renders (got %d)" % len(a.outs))
    if not 0 < a.top <= 1:
        fail("--top %g is not in (0, 1]" % a.top)
    ref = read_rgb(a.ref)
    outs = []
    for p in a.outs:
        o = read_rgb(p)
        if o.shape != ref.shape:
            fail("%s is %dx%d, the reference %dx%d" % (p, o.shape[1], o.shape[0], ref.shape[1],
                                                      ref.shape[0]))
        outs.append(o)
    w = 1.0 / (ref * ref + 0.01)
    rel = [float(np.mean((o - ref) ** 2 * w)) for o in outs]
    var_px = np.var(np.stack(outs), axis=0, ddof=1) * w
    var = float(np.mean(var_px))
    mean_rel = float(np.mean(rel))
    v = np.sort(np.mean(var_px, axis=-1).ravel())
    k = max(1, int(round(a.top * v.size)))
    top = float(v[-k:].sum() / v.sum()) if v.sum() > 0 else 0.0
    print(json.dumps({"n": len(outs), "relmse": mean_rel, "relmse_each": rel, "variance": var,
                      "rest": mean_rel - var,
                      "variance_share": var / mean_rel if mean_rel > 0 else 0.0,
                      "top": a.top, "top_share": top}))


if __name__ == "__main__":
    main()
