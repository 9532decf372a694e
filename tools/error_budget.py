#!/usr/bin/python3
"""Where KPCN's error comes from, and what a perfect demodulated-domain denoiser would leave.

usage: tools/error_budget.py NOISY.exr REF.exr [--model M.safetensors] [--kpcntool PATH] [--eps E]
                             [--color-ref C.exr] [--edges]

--eps is the albedo epsilon of the oracle's demodulation: by default the model's (kpcn.eps), or
0.00316 (Bako 2017's) without --model. --color-ref measures every figure against C's R, G, B
instead of REF's colour (e.g. a 4096-spp colour-only render; REF's buffers still build the
oracles). --edges adds edge_fraction and, for every figure, its contributions to the image
mean from "edges" (pixels whose noisy samples saw more than one surface or texel value:
NOISY's albedo.var > 1e-4, N.var > 1e-4 or Z.var > 1e-6 Z^2) and from the "rest"; the two
add up to the figure.

Both files are kpcn AOV EXRs (REF with its diffuse / specular / albedo buffers, as the
dataset's references are). Prints one JSON object of relMSE values (R, G, B; eps 0.01, as
kpcntool --relmse) against REF's colour (or C's):

  noisy              the noisy colour
  irradiance_oracle  (A_noisy + eps) * D_ref / (A_ref + eps) + S_ref: a network whose diffuse
                     branch returned the reference's own irradiance exactly and whose specular
                     branch returned the reference's specular. The pipeline remodulates with
                     the NOISY albedo (DESIGN.md section 5), so the albedo's sub-pixel coverage
                     error at edges and texture detail stays. (A kernel could in principle do
                     better by weighting neighbours across an edge, producing a non-smooth
                     ratio.)
  diffuse_exact      D_ref + S_noisy (what the noisy specular alone costs)
  specular_exact     D_noisy + S_ref

With --model, also the model's own output split by branch (kpcntool --denoise):
  kpcn               the denoised image
  kpcn_diffuse       its diffuse branch with the reference specular (D_kpcn + S_ref)
  kpcn_specular      its specular branch with the reference diffuse (D_ref + S_kpcn)
  kpcn_top1pct       share of kpcn's error in its worst 1 % of pixels
  kpcn_albedo_exact  the model's output with its diffuse branch remodulated by REF's albedo
                     instead of the noisy one: D_kpcn * (A_ref + eps) / (A_noisy + eps) +
                     S_kpcn, the same network's irradiance and specular, no albedo coverage
                     error (what a perfect albedo buffer would give this model)
The diffuse branch's part D_kpcn is the denoised result of the same input with the specular
buffers zeroed: that branch never reads them, and the specular branch then filters zeros
(exp(0) - 1 = 0), so the split is exact (to float rounding). One coupling is undone by hand:
the denoiser scales both branches' inputs by target / exposure(input) (docs/denoiser.md,
"Exposure"; the target is the model's recorded exposure, none = as rendered), and the
exposure statistic reads diffuse + specular, so the zeroed input is denoised at an exposure
chosen to give it the full input's scale. (The firefly bound's floor, 0.01 x the input's
exposure, is not pinned: a pixel whose irradiance lies between the two floors is bounded in
one run only.)"""
import argparse
import json
import os
import struct
import subprocess
import sys
import tempfile

import kpcn_tools

import numpy as np
import OpenImageIO as oiio


def fail(msg):
    sys.exit("error_budget: " + msg)


def load(path):
    buf = oiio.ImageBuf(path)
    if buf.has_error:
        fail("%s: %s" % (path, buf.geterror()))
    pix = buf.get_pixels(oiio.FLOAT)
    if pix is None:
        fail("%s: cannot read pixels: %s" % (path, buf.geterror()))
    return buf, {n: pix[..., i] for i, n in enumerate(buf.spec().channelnames)}


def rgb(img, prefix, path):
    try:
        return np.stack([img[prefix + c] for c in "RGB"], -1).astype(np.float64)
    except KeyError as e:
        fail("%s has no channel %s" % (path, e))


def relmse_map(x, y):
    return ((x - y) ** 2 / (y ** 2 + 0.01)).mean(-1)


def plane(img, name, path):
    try:
        return img[name].astype(np.float64)
    except KeyError:
        fail("%s has no channel %s" % (path, name))


def edge_mask(img, path):
    """Pixels whose samples saw more than one surface or texel value: the noisy render's
    albedo.var > 1e-4, N.var > 1e-4 or Z.var > 1e-6 Z^2 (thresholds chosen, not derived:
    texture and silhouette edges, where sub-pixel coverage is noisy)."""
    z = plane(img, "Z", path)
    return ((plane(img, "albedo.var", path) > 1e-4) | (plane(img, "N.var", path) > 1e-4)
            | (plane(img, "Z.var", path) > 1e-6 * z * z))


def model_meta(path):
    """A model file's __metadata__ (kpcn_model_save's safetensors header)."""
    try:
        with open(path, "rb") as f:
            n = struct.unpack("<Q", f.read(8))[0]
            return json.loads(f.read(n))["__metadata__"]
    except (OSError, ValueError, KeyError, TypeError, struct.error) as err:
        fail("%s: cannot read the model's header: %s" % (path, err))


def model_exposure(path):
    """The exposure target a model records (kpcn.architecture's "exposure"), 0 if none."""
    try:
        e = float(json.loads(model_meta(path)["kpcn.architecture"]).get("exposure", 0.0))
    except (ValueError, KeyError, TypeError) as err:
        fail("%s: cannot read the model's exposure: %s" % (path, err))
    return float(np.float32(e)) if e > 0 else 0.0  # the library keeps it as a float


def model_eps(path):
    """The albedo epsilon of a model's diffuse demodulation (kpcn.eps)."""
    try:
        return float(model_meta(path)["kpcn.eps"])
    except (ValueError, KeyError, TypeError) as err:
        fail("%s: cannot read the model's eps: %s" % (path, err))


def exposure(tool, path):
    r = subprocess.run([tool, path, "--exposure", "--json"], stdout=subprocess.PIPE,
                       stderr=subprocess.PIPE, text=True)
    if r.returncode != 0:
        fail("kpcntool --exposure on %s: %s" % (path, r.stderr.strip()))
    return json.loads(r.stdout)["exposure"]


def denoise(tool, model, src, dst, opts=""):
    r = subprocess.run([tool, src, "--denoise:model=" + model + opts, "-o", dst],
                       stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if r.returncode != 0:
        fail("kpcntool --denoise on %s: %s" % (src, r.stderr.strip()))
    return rgb(load(dst)[1], "", dst)


def main():
    ap = kpcn_tools.parser(__doc__)
    ap.add_argument("noisy")
    ap.add_argument("ref")
    ap.add_argument("--model")
    ap.add_argument("--kpcntool", default=kpcn_tools.tool_path("kpcntool"))
    ap.add_argument("--eps", type=kpcn_tools.positive_float)
    ap.add_argument("--color-ref")
    ap.add_argument("--edges", action="store_true")
    a = ap.parse_args()
    if a.eps is None:  # the model's own, so the oracle remodulates as its pipeline does
        a.eps = model_eps(a.model) if a.model else 0.00316
    if a.model:
        kpcn_tools.check_executable(a.kpcntool, "kpcntool", fail)
    nbuf, n = load(a.noisy)
    _, r = load(a.ref)
    d_n, s_n, a_n = (rgb(n, p, a.noisy) for p in ("diffuse.", "specular.", "albedo."))
    d_r, s_r, a_r = (rgb(r, p, a.ref) for p in ("diffuse.", "specular.", "albedo."))
    ref = rgb(r, "", a.ref)
    if d_n.shape != ref.shape:
        fail("%s and %s differ in size" % (a.noisy, a.ref))
    if a.color_ref:  # every figure against this colour; REF's buffers still build the oracles
        ref = rgb(load(a.color_ref)[1], "", a.color_ref)
        if ref.shape != d_n.shape:
            fail("%s and %s differ in size" % (a.noisy, a.color_ref))
    maps = {
        "noisy": relmse_map(rgb(n, "", a.noisy), ref),
        "irradiance_oracle": relmse_map((a_n + a.eps) * d_r / (a_r + a.eps) + s_r, ref),
        "diffuse_exact": relmse_map(d_r + s_n, ref),
        "specular_exact": relmse_map(d_n + s_r, ref),
    }
    if a.model:
        with tempfile.TemporaryDirectory() as tmp:
            full = denoise(a.kpcntool, a.model, a.noisy, os.path.join(tmp, "full.exr"))
            spec = nbuf.spec()
            pix = nbuf.get_pixels(oiio.FLOAT)
            for i, name in enumerate(spec.channelnames):
                if name.startswith("specular."):
                    pix[..., i] = 0.0
            nospec = oiio.ImageBuf(spec)
            nospec.set_pixels(oiio.ROI(), pix)
            path = os.path.join(tmp, "nospec.exr")
            if not nospec.write(path):
                fail("cannot write %s: %s" % (path, nospec.geterror()))
            # the full run's colour scale, target / exposure(noisy) (1 as rendered), for the
            # zeroed input too: exposure(nospec) * scale is the target that gives it
            target, opts = model_exposure(a.model), ""
            if target > 0:
                e_full, e_nospec = exposure(a.kpcntool, a.noisy), exposure(a.kpcntool, path)
                if not e_full > 0:
                    opts = ":exposure=off"
                elif e_nospec > 0:
                    opts = ":exposure=%r" % (e_nospec * target / e_full)
            diff = denoise(a.kpcntool, a.model, path, os.path.join(tmp, "diffuse.exr"), opts)
        m_eps = model_eps(a.model)
        maps.update({
            "kpcn": relmse_map(full, ref),
            "kpcn_diffuse": relmse_map(diff + s_r, ref),
            "kpcn_specular": relmse_map(d_r + (full - diff), ref),
            # the pipeline remodulates at the model's eps, whatever --eps gave the oracle
            "kpcn_albedo_exact": relmse_map(full + diff * ((a_r + m_eps) / (a_n + m_eps) - 1), ref),
        })
    out = {k: float(m.mean()) for k, m in maps.items()}
    if a.model:
        err = np.sort(maps["kpcn"].ravel())[::-1]
        out["kpcn_top1pct"] = float(err[:max(1, err.size // 100)].sum() / err.sum())
    if a.edges:
        edge = edge_mask(n, a.noisy)
        out["edge_fraction"] = float(edge.mean())
        out["edges"] = {k: float(m[edge].sum() / m.size) for k, m in maps.items()}
        out["rest"] = {k: float(m[~edge].sum() / m.size) for k, m in maps.items()}
    print(json.dumps(out))


if __name__ == "__main__":
    main()
