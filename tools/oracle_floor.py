#!/usr/bin/python3
"""What a perfect denoiser in KPCN's demodulated domain would still leave (docs/results.md).

usage: tools/oracle_floor.py NOISY.exr REF.exr [EPS]

Both files are kpcn AOV EXRs (REF with its diffuse / specular / albedo buffers, as the
dataset's references are). The pipeline remodulates with the NOISY albedo
(c = d_out * (albedo + eps) + exp(s_out) - 1, DESIGN.md section 5), so a network whose
diffuse branch returned the reference's own irradiance D_ref / (A_ref + eps) exactly, and
whose specular branch returned the reference's specular exactly, would output
(A_noisy + eps) * D_ref / (A_ref + eps) + S_ref: at edges and texture detail the noisy
albedo's sub-pixel coverage error stays in the image. (A kernel can in principle do better,
by weighting neighbours across an edge, but it must then produce a non-smooth ratio.)
Prints one JSON object of relMSE values (R, G, B; eps 0.01, as kpcntool --relmse) against
REF's colour: noisy, irradiance_oracle (the above), diffuse_exact (noisy specular kept),
specular_exact (noisy diffuse kept)."""
import json
import sys

import numpy as np
import OpenImageIO as oiio


def load(path):
    buf = oiio.ImageBuf(path)
    if buf.has_error:
        sys.exit("oracle_floor: %s: %s" % (path, buf.geterror()))
    pix = buf.get_pixels(oiio.FLOAT)
    names = buf.spec().channelnames
    return {n: pix[..., i] for i, n in enumerate(names)}


def rgb(img, prefix, path):
    try:
        return np.stack([img[prefix + c] for c in "RGB"], -1).astype(np.float64)
    except KeyError as e:
        sys.exit("oracle_floor: %s has no channel %s" % (path, e))


def relmse(x, y):
    return float(np.mean((x - y) ** 2 / (y ** 2 + 0.01)))


def main():
    if len(sys.argv) not in (3, 4):
        sys.exit(__doc__.split("\n\n")[1])
    npath, rpath = sys.argv[1], sys.argv[2]
    eps = float(sys.argv[3]) if len(sys.argv) == 4 else 0.00316
    n, r = load(npath), load(rpath)
    if n["R"].shape != r["R"].shape:
        sys.exit("oracle_floor: %s and %s differ in size" % (npath, rpath))
    d_n, s_n, a_n = (rgb(n, p, npath) for p in ("diffuse.", "specular.", "albedo."))
    d_r, s_r, a_r = (rgb(r, p, rpath) for p in ("diffuse.", "specular.", "albedo."))
    ref = rgb(r, "", rpath)
    out = {
        "noisy": relmse(rgb(n, "", npath), ref),
        "irradiance_oracle": relmse((a_n + eps) * d_r / (a_r + eps) + s_r, ref),
        "diffuse_exact": relmse(d_r + s_n, ref),
        "specular_exact": relmse(d_n + s_r, ref),
    }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
