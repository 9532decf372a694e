#!/usr/bin/python3
"""Checks kpcntool --kernels files against the denoised image: usage
kernels_check.py AOV.exr KERNELS_DIFFUSE.exr KERNELS_SPECULAR.exr DENOISED.exr

Each file's kernels (kernel.TTT, tap t = dy*K + dx, clamped reads) are applied kpcn:kernelPasses
times to its pre.R/G/B, in float64, and the two branches recombined as kpcn/denoise.h says:
(diffuse * (albedo + kpcn:eps) + exp(specular) - 1) / kpcn:exposureScale. Exits 1 unless that
is the denoised image (max relative error 1e-4, floor 1e-3) and every kernel is >= 0 and sums
to 1."""
import sys

import numpy as np
import OpenImageIO as oiio


def load(path):
    buf = oiio.ImageBuf(path)
    pix = buf.get_pixels(oiio.FLOAT)
    if pix is None:
        sys.exit("kernels_check: cannot read %s: %s" % (path, buf.geterror()))
    return buf.spec(), {n: pix[..., i].astype(np.float64) for i, n in enumerate(buf.spec().channelnames)}


def branch(path, want):
    spec, ch = load(path)
    K, passes = spec.getattribute("kpcn:kernelSize"), spec.getattribute("kpcn:kernelPasses")
    if spec.getattribute("kpcn:branch") != want or not K or not passes:
        sys.exit("kernels_check: %s: branch %r, kernelSize %r, kernelPasses %r" %
                 (path, spec.getattribute("kpcn:branch"), K, passes))
    if spec.nchannels != 3 + K * K:
        sys.exit("kernels_check: %s has %d channels, not 3 + %d" % (path, spec.nchannels, K * K))
    w = np.stack([ch["kernel.%03d" % t] for t in range(K * K)])
    if w.min() < 0 or np.abs(w.sum(0) - 1).max() > 1e-5:
        sys.exit("kernels_check: %s: weights min %g, |sum - 1| up to %g" %
                 (path, w.min(), np.abs(w.sum(0) - 1).max()))
    f = np.stack([ch["pre." + c] for c in "RGB"])
    H, W = f.shape[1:]
    r = K // 2
    for _ in range(passes):
        pad = np.pad(f, ((0, 0), (r, r), (r, r)), mode="edge")
        f = sum(w[t] * pad[:, t // K:t // K + H, t % K:t % K + W] for t in range(K * K))
    return spec, f


_, aov = load(sys.argv[1])
dspec, d = branch(sys.argv[2], "diffuse")
sspec, s = branch(sys.argv[3], "specular")
_, den = load(sys.argv[4])
scale, eps = dspec.getattribute("kpcn:exposureScale"), dspec.getattribute("kpcn:eps")
if sspec.getattribute("kpcn:exposureScale") != scale:
    sys.exit("kernels_check: the branches were shown the input at different exposures")
alb = np.stack([aov["albedo." + c] for c in "RGB"])
want = np.stack([den[c] for c in "RGB"])
got = (d * (alb + eps) + np.expm1(s)) / scale
err = (np.abs(got - want) / (1e-3 + np.abs(want))).max()
print("kernels applied %d time(s) and recombined vs --denoise: max rel err %.3g" %
      (dspec.getattribute("kpcn:kernelPasses"), err))
sys.exit(0 if err < 1e-4 else 1)
