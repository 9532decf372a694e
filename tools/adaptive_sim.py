#!/usr/bin/env python3
"""Would spending samples on edges help the shipped model? A simulation, not a sampler.

For each of four seeds it renders a held-out scene at a uniform 16 spp, and an "adaptive"
frame at the same mean spp: the fraction F = (16 - L) / (H - L) of pixels with the strongest
feature edges (relative depth + normal + relative albedo gradient of an L-spp render) taken
from an H-spp render, the rest from that L-spp render, so the mean is exactly 16 spp. Keep L
and H powers of two: the Owen-scrambled Sobol sampler stratifies best there (at 11 spp a
frame is about 25 % noisier than 1/spp predicts). Both are denoised with MODEL and
measured against REF (relMSE, kpcntool); the noisy frames too. Results: docs/training-log.md,
"Session 18".
  python3 tools/adaptive_sim.py DATASET_DIR SCENE L H MODEL [KPCN_BIN]
  e.g. python3 tools/adaptive_sim.py dataset/v1 textures 8 64 testdata/models/kpcn-cpu.safetensors
Needs the Python OpenImageIO module (Debian: python3-openimageio).
"""
import atexit, os, shutil, subprocess, sys, tempfile

import numpy as np
import OpenImageIO as oiio

USAGE = "usage: python3 tools/adaptive_sim.py DATASET_DIR SCENE L H MODEL [KPCN_BIN]"
if len(sys.argv) not in (6, 7):
    sys.exit(USAGE)
ds, scene, model = sys.argv[1], sys.argv[2], sys.argv[5]
try:
    lo_spp, hi_spp = int(sys.argv[3]), int(sys.argv[4])
except ValueError:
    sys.exit("adaptive_sim: L and H must be integers (got %r, %r)\n%s" % (sys.argv[3], sys.argv[4], USAGE))
if not 0 < lo_spp < 16 < hi_spp:
    sys.exit("adaptive_sim: need L < 16 < H")
frac = (16 - lo_spp) / (hi_spp - lo_spp)
bindir = sys.argv[6] if len(sys.argv) > 6 else os.path.join(os.path.dirname(__file__), "..", "build", "tools")
render_bin = os.path.join(bindir, "kpcn-render", "kpcn-render")
tool_bin = os.path.join(bindir, "kpcntool", "kpcntool")
ref = f"{ds}/renders/{scene}/v000_ref4096spp.exr"
for path, what in ((ref, "4096-spp reference (render it first: docs/dataset.md)"),
                   (f"{ds}/scenes/{scene}/v000.json", "scene variant"), (model, "model"),
                   (render_bin, "kpcn-render"), (tool_bin, "kpcntool")):
    if not os.path.isfile(path):
        sys.exit(f"adaptive_sim: no {what} at '{path}'")
res = "%dx%d" % (oiio.ImageBuf(ref).spec().width, oiio.ImageBuf(ref).spec().height)
work = tempfile.mkdtemp()
atexit.register(shutil.rmtree, work, True)


def run(argv, **kw):
    """A tool's failure ends the script with its message, not a traceback."""
    r = subprocess.run(argv, capture_output=True, text=True, **kw)
    if r.returncode != 0:
        sys.exit(f"adaptive_sim: {os.path.basename(argv[0])} failed: {r.stderr.strip()}")
    return r


def render(spp, seed):
    out = f"{work}/{spp}_{seed}.exr"
    run([render_bin, f"{ds}/scenes/{scene}/v000.json", "-o", out, "--spp", str(spp), "--seed",
         str(seed), "--resolution", res, "--quiet"])
    return out


def relmse(path):
    return float(run([tool_bin, path, ref, "--ch", "R,G,B", "--relmse"]).stdout.split()[-1])


def denoised(path):
    out = f"{work}/d.exr"
    run([tool_bin, path, "--denoise:model=" + model, "-o", out])
    return out


def edge_strength(names, px):
    """Largest difference to a 4-neighbour: depth and albedo relative, normal absolute."""
    def planes(*ch):
        return np.stack([px[:, :, names.index(c)] for c in ch], -1)
    total = np.zeros(px.shape[:2])
    for x, rel in ((planes("Z"), True), (planes("N.X", "N.Y", "N.Z"), False),
                   (planes("albedo.R", "albedo.G", "albedo.B"), True)):
        g = np.zeros(px.shape[:2])
        for dy, dx in ((0, 1), (1, 0), (0, -1), (-1, 0)):
            d = np.abs(np.roll(np.roll(x, dy, 0), dx, 1) - x)
            if rel:
                d = d / (np.abs(x) + 1e-3)
            g = np.maximum(g, d.sum(-1))
        total += g
    return total


rows = {k: [] for k in ("noisy16", "kpcn16", "noisy_adaptive", "kpcn_adaptive")}
for seed in (1001, 1002, 1003, 1004):
    uniform = render(16, seed)
    rows["noisy16"].append(relmse(uniform))
    rows["kpcn16"].append(relmse(denoised(uniform)))
    lo, hi = oiio.ImageBuf(render(lo_spp, seed + 100)), oiio.ImageBuf(render(hi_spp, seed + 200))
    names = list(lo.spec().channelnames)
    a, b = lo.get_pixels(oiio.FLOAT), hi.get_pixels(oiio.FLOAT)
    e = edge_strength(names, a)
    mask = e > np.quantile(e, 1 - frac)
    a[mask] = b[mask]
    mixed = oiio.ImageBuf(lo.spec())
    mixed.set_pixels(oiio.ROI(), a)
    if not mixed.write(f"{work}/adaptive.exr"):
        sys.exit("adaptive_sim: cannot write the mixed frame: " + mixed.geterror())
    rows["noisy_adaptive"].append(relmse(f"{work}/adaptive.exr"))
    rows["kpcn_adaptive"].append(relmse(denoised(f"{work}/adaptive.exr")))
mean_spp = frac * hi_spp + (1 - frac) * lo_spp
print(f"{scene} F={frac:.3f} H={hi_spp} L={lo_spp} mean spp {mean_spp:.2f}: " +
      " ".join(f"{k} {np.mean(v):.3e}" for k, v in rows.items()))
