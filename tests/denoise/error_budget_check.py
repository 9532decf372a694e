#!/usr/bin/python3
"""Independent checks of tools/error_budget.py, run by test_error_budget.sh.

usage: error_budget_check.py SCRIPT KPCNTOOL DIR   (DIR holds denoise_fixture's aov.exr and
model.safetensors; the fixtures below are written there)

1. Exact identities on pairs where one buffer of NOISY differs from REF by a known amount.
   Diffuse, specular and albedo are rounded to multiples of 2^-10 and colour = diffuse +
   specular, so every sum below is exact in float32 and float64 and the identities hold to
   the bit, not to a tolerance:
   - only diffuse differs (d): diffuse_exact = D_ref + S_noisy = colour_ref -> 0;
     specular_exact = D_noisy + S_ref = colour_noisy -> == noisy; the albedos agree, so the
     oracle is D_ref + S_ref -> 0 (to the rounding of x * D / x); noisy = mean(d^2 / (C^2 + 0.01)).
   - only specular differs: the same with the branches swapped.
   - only albedo differs, A_noisy = 2 A_ref + eps (eps = 2^-8, given as --eps): noisy and both
     *_exact are 0, the oracle remodulates D_ref by (A_noisy + eps) / (A_ref + eps) = 2 exactly:
     irradiance_oracle = mean(D_ref^2 / (C^2 + 0.01)).
2. The four figures that need no network, recomputed here from the definitions
   (docs/results.md, the script's docstring) on a pair where every buffer differs, at the
   default albedo eps (0.00316, the pipeline's) and another: 1e-9 relative. noisy also equals
   kpcntool --relmse. With --model and no --eps, the oracle uses the model's eps (a copy of the
   fixture model recording 0.05).
3. With the tiny fixture model, as saved (no exposure recorded: the input is denoised as
   rendered) and with an exposure target written into it (the denoiser then scales both
   branches' inputs by target / exposure(input)):
   - NOISY and REF without specular: the zeroed input is the input itself, so
     kpcn_specular = 0 exactly and kpcn_diffuse == kpcn.
   - every buffer differs: the specular branch's part, computed here the other way round (the
     input with diffuse.* zeroed, denoised at the full input's colour scale; the diffuse branch
     then filters zeros), must give the script's kpcn_specular, and full - it its kpcn_diffuse;
     and full = (diffuse zeroed) + (specular zeroed) pixelwise, the premise of the split;
     kpcn_albedo_exact from that diffuse part remodulated by REF's albedo at the model's eps
     (also when --eps moves the oracle's).
4. --color-ref: REF's own file changes nothing, another colour is what the network-free figures
   are measured against (recomputed); --edges on a copy of NOISY whose variance buffers mark
   known rows (each criterion alone, and values just below two thresholds): the edge fraction
   is their share, the two parts add up to each figure, the figures are those without
   --edges; a colour reference of another size and a noisy file without N.var are refused.
Prints the measured figures."""
import json
import os
import struct
import subprocess
import sys

import numpy as np
import OpenImageIO as oiio

SCRIPT, TOOL, DIR = sys.argv[1:4]
RGB = "RGB"


def fail(msg):
    print("FAIL: " + msg)
    sys.exit(1)


def read(path):
    """name -> float64 plane, through ImageInput (the script reads through ImageBuf)."""
    inp = oiio.ImageInput.open(path)
    if not inp:
        fail("cannot open %s: %s" % (path, oiio.geterror()))
    spec = inp.spec()
    px = inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
    inp.close()
    return spec, {n: px[..., i].astype(np.float64) for i, n in enumerate(spec.channelnames)}


def get(ch, pre):
    return np.stack([ch[pre + c] for c in RGB], -1)


def put(ch, pre, v):
    for i, c in enumerate(RGB):
        ch[pre + c] = v[..., i]


def write(path, spec, ch, exact=True):
    px = np.stack([ch[n] for n in spec.channelnames], -1)
    if exact and not np.array_equal(px.astype(np.float32).astype(np.float64), px):
        fail("fixture %s is not exact in float32" % path)
    out = oiio.ImageOutput.create(path)
    if not out or not out.open(path, spec) or not out.write_image(px.astype(np.float32)):
        fail("cannot write %s: %s" % (path, oiio.geterror()))
    out.close()
    return path


def budget(noisy, ref, *args):
    r = subprocess.run([sys.executable, SCRIPT, noisy, ref, *args], stdout=subprocess.PIPE,
                       stderr=subprocess.PIPE, text=True)
    if r.returncode != 0:
        fail("error_budget.py %s %s %s: %s" % (noisy, ref, " ".join(args), r.stderr.strip()))
    return json.loads(r.stdout)


def relmse(x, y):
    return float(np.mean((x - y) ** 2 / (y ** 2 + 0.01)))


def close(a, b, tol):
    return abs(a - b) <= tol * max(abs(a), abs(b))


def show(name, d):
    print("%-22s %s" % (name, " ".join("%s=%.6g" % kv for kv in d.items())))


spec, base = read(os.path.join(DIR, "aov.exr"))
q = lambda v: np.round(v * 1024.0) / 1024.0
D, S, A = q(get(base, "diffuse.")), q(get(base, "specular.")), q(get(base, "albedo."))
if not A.min() > 0:
    fail("fixture albedo not positive")
C = D + S
w = C ** 2 + 0.01
ref = dict(base)
put(ref, "diffuse.", D), put(ref, "specular.", S), put(ref, "albedo.", A), put(ref, "", C)
REF = write(os.path.join(DIR, "eb_ref.exr"), spec, ref)
rng = np.random.default_rng(7)

# 1. one buffer differs: the other branch's exact figure is 0, this one's is all of noisy
for name, base_buf, other in (("diffuse", D, "specular"), ("specular", S, "diffuse")):
    delta = rng.integers(0, 129, C.shape) / 1024.0  # 0 .. 1/8, exact; a new draw each
    x = dict(ref)
    put(x, name + ".", base_buf + delta), put(x, "", C + delta)
    j = budget(write(os.path.join(DIR, "eb_%s.exr" % name), spec, x), REF)
    show(name + " perturbed", j)
    if not (j[name + "_exact"] == 0.0 and j[other + "_exact"] == j["noisy"] > 0):
        fail("only %s perturbed: want %s_exact == 0 and %s_exact == noisy: %s"
             % (name, name, other, j))
    if not (j["irradiance_oracle"] < 1e-28
            and close(j["noisy"], float(np.mean(delta ** 2 / w)), 1e-12)):
        fail("only %s perturbed: want oracle 0, noisy mean(d^2/(C^2+0.01)): %s" % (name, j))
EPS = 2.0 ** -8
x = dict(ref)
put(x, "albedo.", 2 * A + EPS)
j = budget(write(os.path.join(DIR, "eb_albedo.exr"), spec, x), REF, "--eps", repr(EPS))
show("albedo x2 (+eps)", j)
want = float(np.mean(D ** 2 / w))
if not (j["noisy"] == j["diffuse_exact"] == j["specular_exact"] == 0.0 and
        close(j["irradiance_oracle"], want, 1e-12)):
    fail("only albedo perturbed: want 0, 0, 0 and oracle %.17g: %s" % (want, j))

# 2. every buffer differs (float32 values, colour = diffuse + specular in float32)
f32 = lambda v: v.astype(np.float32).astype(np.float64)
u = lambda: rng.uniform(-1.0, 1.0, C.shape)
_, orig = read(os.path.join(DIR, "aov.exr"))
Dr, Sr, Ar, Cr = (get(orig, p) for p in ("diffuse.", "specular.", "albedo.", ""))
Dn, Sn, An = f32(Dr * (1 + 0.4 * u())), f32(Sr * (1 + 0.6 * u())), f32(Ar * (1 + 0.3 * u()))
Cn = (Dn.astype(np.float32) + Sn.astype(np.float32)).astype(np.float64)
noisy = dict(orig)
put(noisy, "diffuse.", Dn), put(noisy, "specular.", Sn), put(noisy, "albedo.", An), put(noisy, "", Cn)
NOISY = write(os.path.join(DIR, "eb_noisy.exr"), spec, noisy)
AOV = os.path.join(DIR, "aov.exr")
for eps in (None, 0.05):
    j = budget(NOISY, AOV, *(["--eps", repr(eps)] if eps else []))
    e = 0.00316 if eps is None else eps
    want = {"noisy": relmse(Cn, Cr),
            "irradiance_oracle": relmse((An + e) * Dr / (Ar + e) + Sr, Cr),
            "diffuse_exact": relmse(Dr + Sn, Cr),
            "specular_exact": relmse(Dn + Sr, Cr)}
    show("all perturbed eps=%g" % e, j)
    for k, v in want.items():
        if not (v > 0 and close(j[k], v, 1e-9)):
            fail("%s (eps %g): script %.17g, recomputed %.17g" % (k, e, j[k], v))
r = subprocess.run([TOOL, "--json", NOISY, AOV, "--ch", "R,G,B", "--relmse"],
                   stdout=subprocess.PIPE, text=True)
if r.returncode != 0 or not close(json.loads(r.stdout)["relmse"], j["noisy"], 1e-6):
    fail("noisy %.17g != kpcntool --relmse %s" % (j["noisy"], r.stdout.strip()))

# 3. with a model
MODEL = os.path.join(DIR, "model.safetensors")
TARGET = 0.5  # exact in float32, as the library keeps it


def read_model(path):
    """A safetensors file's JSON header and the bytes after it."""
    with open(path, "rb") as f:
        n = struct.unpack("<Q", f.read(8))[0]
        return json.loads(f.read(n)), f.read()


def with_arch(src, dst, key, value):
    """A copy of the model at src whose architecture records key = value (eps also in the
    header's kpcn.eps, which the loader checks against it)."""
    head, data = read_model(src)
    arch = json.loads(head["__metadata__"]["kpcn.architecture"])
    if key == "exposure" and "exposure" in arch:
        fail("the fixture model already records an exposure")
    arch[key] = value
    if key == "eps":
        head["__metadata__"]["kpcn.eps"] = repr(value)
    head["__metadata__"]["kpcn.architecture"] = json.dumps(arch, separators=(",", ":"))
    h = json.dumps(head, separators=(",", ":")).encode()
    h += b" " * (-len(h) % 8)
    with open(dst, "wb") as f:
        f.write(struct.pack("<Q", len(h)) + h + data)
    return dst


def model_eps(path):
    return float(read_model(path)[0]["__metadata__"]["kpcn.eps"])


def exposure(path):
    r = subprocess.run([TOOL, path, "--exposure", "--json"], stdout=subprocess.PIPE, text=True)
    if r.returncode != 0:
        fail("kpcntool --exposure %s" % path)
    return json.loads(r.stdout)["exposure"]


def denoise(src, model, opts, name):
    dst = os.path.join(DIR, name)
    if subprocess.run([TOOL, src, "--denoise:model=" + model + opts, "-o", dst]).returncode:
        fail("kpcntool --denoise %s" % src)
    return get(read(dst)[1], "")


def zeroed(ch, pre, name):
    y = dict(ch)
    for k in y:
        if k.startswith(pre):
            y[k] = np.zeros_like(y[k])
    return write(os.path.join(DIR, name), spec, y, exact=False)


nospec_ref = dict(ref)
put(nospec_ref, "specular.", 0 * S), put(nospec_ref, "", D)
NSREF = write(os.path.join(DIR, "eb_nospec_ref.exr"), spec, nospec_ref)
nospec_noisy = dict(noisy)
for k in nospec_noisy:
    if k.startswith("specular."):
        nospec_noisy[k] = np.zeros_like(nospec_noisy[k])
put(nospec_noisy, "", Dn)
NSNOISY = write(os.path.join(DIR, "eb_nospec_noisy.exr"), spec, nospec_noisy)
NODIFF = zeroed(noisy, "diffuse.", "eb_nodiff.exr")
NOSPEC = zeroed(noisy, "specular.", "eb_nospec.exr")
e_full, e_nodiff, e_nospec = exposure(NOISY), exposure(NODIFF), exposure(NOSPEC)
if not (e_full > 0 and e_nodiff > 0 and e_nospec > 0):
    fail("fixture exposures %g %g %g" % (e_full, e_nodiff, e_nospec))
EXPMODEL = with_arch(MODEL, os.path.join(DIR, "eb_model_exposure.safetensors"), "exposure", TARGET)
# without --eps the oracle demodulates at the model's own eps (0.05 here), as its pipeline does
EPSMODEL = with_arch(MODEL, os.path.join(DIR, "eb_model_eps.safetensors"), "eps", 0.05)
j = budget(NOISY, AOV, "--model", EPSMODEL, "--kpcntool", TOOL)
e = 0.05
if not close(j["irradiance_oracle"], relmse((An + e) * Dr / (Ar + e) + Sr, Cr), 1e-9):
    fail("irradiance_oracle with a model of eps 0.05 and no --eps: %.17g" % j["irradiance_oracle"])
print("exposures: full %.6g, diffuse zeroed %.6g, specular zeroed %.6g; target %g"
      % (e_full, e_nodiff, e_nospec, TARGET))
for model, target in ((MODEL, 0.0), (EXPMODEL, TARGET)):
    tag = "exposure %g" % target if target else "as rendered"
    j = budget(NSNOISY, NSREF, "--model", model, "--kpcntool", TOOL)
    show("no specular, " + tag, j)
    if not (j["kpcn_specular"] == 0.0 and j["kpcn"] > 0 and close(j["kpcn_diffuse"], j["kpcn"], 1e-12)):
        fail("no specular (%s): want kpcn_specular == 0, kpcn_diffuse == kpcn: %s" % (tag, j))
    # the other way round: each branch alone, at the full input's colour scale
    pin = lambda e: ":exposure=%r" % (e * target / e_full) if target else ""
    full = denoise(NOISY, model, "", "eb_full.exr")
    spec_part = denoise(NODIFF, model, pin(e_nodiff), "eb_spec_part.exr")
    diff_part = denoise(NOSPEC, model, pin(e_nospec), "eb_diff_part.exr")
    res = np.abs(full - diff_part - spec_part).max() / np.abs(full).max()
    if not res < 1e-6:
        fail("%s: full != diffuse part + specular part pixelwise (max rel %.3g)" % (tag, res))
    j = budget(NOISY, AOV, "--model", model, "--kpcntool", TOOL)
    show("all perturbed, " + tag, j)
    me = model_eps(model)  # the pipeline remodulates by (albedo + the model's eps)
    want = {"kpcn": relmse(full, Cr), "kpcn_specular": relmse(Dr + spec_part, Cr),
            "kpcn_diffuse": relmse(full - spec_part + Sr, Cr),
            "kpcn_albedo_exact": relmse(spec_part + (full - spec_part) * (Ar + me) / (An + me), Cr)}
    dev = max(abs(j[k] / v - 1) for k, v in want.items())
    print("  split residual %.3g (max |full - parts| / max |full|), figures within %.3g" % (res, dev))
    for k, v in want.items():
        if not (v > 0 and close(j[k], v, 1e-6)):
            fail("%s (%s): script %.9g, via the zeroed-diffuse run %.9g" % (k, tag, j[k], v))
    # --eps moves the oracle only: the model's output is remodulated at the model's eps
    j2 = budget(NOISY, AOV, "--model", model, "--kpcntool", TOOL, "--eps", "0.5")
    if not (j2["kpcn_albedo_exact"] == j["kpcn_albedo_exact"]
            and j2["irradiance_oracle"] != j["irradiance_oracle"]):
        fail("--eps 0.5 (%s): kpcn_albedo_exact %.17g (want %.17g), oracle %.17g (want it moved)"
             % (tag, j2["kpcn_albedo_exact"], j["kpcn_albedo_exact"], j2["irradiance_oracle"]))

# 4. --color-ref and --edges
# --color-ref REF's own file changes nothing; another colour is what every figure is measured
# against (recomputed here for the network-free ones)
j0 = budget(NOISY, AOV, "--model", MODEL, "--kpcntool", TOOL)
if budget(NOISY, AOV, "--model", MODEL, "--kpcntool", TOOL, "--color-ref", AOV) != j0:
    fail("--color-ref REF changed the figures")
C2 = f32(Cr * (1 + 0.2 * u()))
c2 = dict(orig)
put(c2, "", C2)
COLOR2 = write(os.path.join(DIR, "eb_color2.exr"), spec, c2)
j = budget(NOISY, AOV, "--color-ref", COLOR2)
e = 0.00316
want = {"noisy": relmse(Cn, C2), "irradiance_oracle": relmse((An + e) * Dr / (Ar + e) + Sr, C2),
        "diffuse_exact": relmse(Dr + Sn, C2), "specular_exact": relmse(Dn + Sr, C2)}
show("--color-ref other", j)
for k, v in want.items():
    if not (v > 0 and close(j[k], v, 1e-9)):
        fail("--color-ref %s: script %.17g, recomputed %.17g" % (k, j[k], v))
# --edges: on a copy of NOISY whose variance buffers mark known pixels (each criterion on its
# own rows, one just below its threshold), the edge fraction is that count and the two parts
# add up to each figure, which --edges leaves as it is without it
ev = dict(noisy)
H = ev["Z"].shape[0]
rows = np.arange(H)[:, None] + 0 * ev["Z"]
for k in ("albedo.var", "N.var", "Z.var"):
    ev[k] = np.zeros_like(ev[k])
ev["albedo.var"][rows % 5 == 0] = 2e-4
ev["N.var"][rows % 5 == 1] = 2e-4
ev["Z.var"][rows % 5 == 2] = (2e-6 * ev["Z"] ** 2)[rows % 5 == 2]
ev["Z.var"][rows % 5 == 3] = (0.5e-6 * ev["Z"] ** 2)[rows % 5 == 3]  # below: not an edge
ev["albedo.var"][rows % 5 == 4] = 0.5e-4  # below: not an edge
EDGES = write(os.path.join(DIR, "eb_edges.exr"), spec, ev, exact=False)
want_frac = float(np.mean(rows % 5 < 3))
plain = budget(EDGES, AOV, "--model", MODEL, "--kpcntool", TOOL)
j = budget(EDGES, AOV, "--model", MODEL, "--kpcntool", TOOL, "--edges")
show("--edges", {"edge_fraction": j["edge_fraction"], "want": want_frac})
if not (j["edge_fraction"] == want_frac and 0 < want_frac < 1):
    fail("edge_fraction %.17g, want %.17g" % (j["edge_fraction"], want_frac))
for k, v in plain.items():
    if k == "kpcn_top1pct":
        continue
    parts = j["edges"][k] + j["rest"][k]
    if not (j[k] == v and close(parts, v, 1e-12) and min(j["edges"][k], j["rest"][k]) > 0):
        fail("--edges %s: %.17g = edges %.17g + rest %.17g (whole %.17g)"
             % (k, v, j["edges"][k], j["rest"][k], j[k]))
# bad input: a colour reference of another size, a noisy file without N.var under --edges
def refused(args, needle, what):
    r = subprocess.run([sys.executable, SCRIPT, *args], stdout=subprocess.PIPE,
                       stderr=subprocess.PIPE, text=True)
    if r.returncode == 0 or needle not in r.stderr:
        fail("%s: exit %d, stderr %r (want an error naming %s)" % (what, r.returncode, r.stderr, needle))


small = oiio.ImageSpec(8, 8, 3, oiio.FLOAT)
small.channelnames = ("R", "G", "B")
SMALL = os.path.join(DIR, "eb_small.exr")
out = oiio.ImageOutput.create(SMALL)
if not out or not out.open(SMALL, small) or not out.write_image(np.ones((8, 8, 3), np.float32)):
    fail("cannot write %s" % SMALL)
out.close()
refused([NOISY, AOV, "--color-ref", SMALL], "eb_small.exr", "--color-ref of another size")
names = [n for n in spec.channelnames if n != "N.var"]
nov = oiio.ImageSpec(spec.width, spec.height, len(names), oiio.FLOAT)
nov.channelnames = tuple(names)
NOVAR = write(os.path.join(DIR, "eb_novar.exr"), nov, {n: noisy[n] for n in names}, exact=False)
refused([NOVAR, AOV, "--edges"], "N.var", "--edges without N.var")
print("error_budget_check: all passed")
