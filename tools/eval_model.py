#!/usr/bin/python3
"""Scores a model on the rendered pairs of one or more datasets, as model changes are judged.

usage: tools/eval_model.py MODEL.safetensors DATASET_DIR... [--variants LIST] [--spp LIST]
                           [--ref-spp N] [--kpcntool PATH] [--denoise-opts OPTS]
                           [--pairs OUT.tsv]

Every pair is DATASET_DIR/renders/<scene>/v<NNN>_<spp>spp.exr against the same variant's
v<NNN>_ref<S>spp.exr (the dataset's reference; kpcn-dataset's layout); where a variant has
several (training_data.sh adds 4096-spp ones to v1), the one of most samples, or the one of
--ref-spp N samples, which every variant must then have. --variants keeps only
the given variant numbers (v2val and v3val: 1,2, since v000 is the authored scene that the
training stores hold); --spp keeps only those sample counts (default: every one found). Each
noisy render is denoised by `kpcntool NOISY --denoise:model=MODEL` (plus --denoise-opts, e.g.
`:exposure=off`), and scored as docs/results.md scores: relMSE on linear R, G, B (eps 0.01)
and PSNR on sRGB-encoded [0, 1]-clamped R, G, B. Prints one JSON object: the number of
pairs, the geometric and arithmetic mean of relMSE and the mean PSNR. --pairs writes one
line per pair (dataset, scene, variant, spp, relMSE, PSNR).
"""
import argparse
import json
import math
import os
import re
import subprocess
import sys
import tempfile

import kpcn_tools

PAIR = re.compile(r"^v(\d+)_(\d+)spp\.exr$")
REF = re.compile(r"^v(\d+)_ref(\d+)spp\.exr$")


def fail(msg):
    sys.exit("eval_model: " + msg)


def int_list(text, what):
    try:
        vals = [int(v) for v in text.split(",")]
    except ValueError:
        fail("%s '%s' is not a comma-separated list of integers" % (what, text))
    if not vals or min(vals) < 0:
        fail("%s '%s' is not a list of non-negative integers" % (what, text))
    return set(vals)


def pairs(dataset, variants, spps, ref_spp):
    """(scene, variant, spp, noisy path, reference path) of every pair in DATASET/renders."""
    root = os.path.join(dataset, "renders")
    if not os.path.isdir(root):
        fail("'%s' has no renders/ folder (not a kpcn-dataset directory?)" % dataset)
    out = []
    for scene in sorted(os.listdir(root)):
        d = os.path.join(root, scene)
        if not os.path.isdir(d):
            continue
        names = os.listdir(d)
        refs = {}
        for n in names:
            m = REF.match(n)
            if m:
                refs.setdefault(int(m.group(1)), []).append((int(m.group(2)), n))
        for n in sorted(names):
            m = PAIR.match(n)
            if not m:
                continue
            v, spp = int(m.group(1)), int(m.group(2))
            if (variants and v not in variants) or (spps and spp not in spps):
                continue
            if v not in refs:
                fail("%s has no reference (v%03d_ref*spp.exr) beside it" % (os.path.join(d, n), v))
            if ref_spp is None:
                ref = max(refs[v])[1]
            else:
                ref = dict(refs[v]).get(ref_spp)
                if ref is None:
                    fail("%s has no %d-spp reference (v%03d_ref%dspp.exr; it has %s)" % (
                        os.path.join(d, n), ref_spp, v, ref_spp,
                        ", ".join("%d spp" % r for r, _ in sorted(refs[v]))))
            out.append((scene, v, spp, os.path.join(d, n), os.path.join(d, ref)))
    return out


def run(cmd):
    r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if r.returncode != 0:
        fail("%s failed: %s" % (" ".join(cmd[:3]), r.stderr.strip()))
    return r.stdout


def main():
    ap = kpcn_tools.parser(__doc__)
    ap.add_argument("model")
    ap.add_argument("datasets", nargs="+")
    ap.add_argument("--variants")
    ap.add_argument("--spp")
    ap.add_argument("--ref-spp")
    ap.add_argument("--kpcntool", default=kpcn_tools.tool_path("kpcntool"))
    ap.add_argument("--denoise-opts", default="")
    ap.add_argument("--pairs")
    a = ap.parse_args()
    kpcn_tools.check_executable(a.kpcntool, "kpcntool", fail)
    if a.pairs:
        kpcn_tools.check_output(a.pairs, "--pairs", fail)
    if not os.path.isfile(a.model):
        fail("no model file '%s'" % a.model)
    variants = int_list(a.variants, "--variants") if a.variants else None
    spps = int_list(a.spp, "--spp") if a.spp else None
    ref_spp = None
    if a.ref_spp is not None:
        r = int_list(a.ref_spp, "--ref-spp")
        if len(r) != 1 or min(r) < 1:
            fail("--ref-spp '%s' is not one positive sample count" % a.ref_spp)
        ref_spp = r.pop()
    jobs = [(ds,) + p for ds in a.datasets for p in pairs(ds, variants, spps, ref_spp)]
    if not jobs:
        fail("no pairs found in %s" % ", ".join(a.datasets))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "denoised.exr")
        for ds, scene, v, spp, noisy, ref in jobs:
            run([a.kpcntool, noisy, "--denoise:model=" + a.model + a.denoise_opts, "-o", out])
            d = json.loads(run([a.kpcntool, out, ref, "--ch", "R,G,B", "--relmse",
                                "--psnr:display=srgb", "--json"]))
            rows.append((ds, scene, v, spp, d["relmse"], d["psnr"]))
    rel = [r[4] for r in rows]
    if min(rel) <= 0:
        fail("a pair has relMSE 0: its geometric mean is undefined")
    if a.pairs:
        with open(a.pairs, "w") as f:
            for r in rows:
                f.write("%s\t%s\tv%03d\t%d\t%.9g\t%.9g\n" % r)
    print(json.dumps({
        "pairs": len(rows),
        "geomean": math.exp(sum(math.log(x) for x in rel) / len(rel)),
        "mean": sum(rel) / len(rel),
        "psnr": sum(r[5] for r in rows) / len(rows),
    }))


if __name__ == "__main__":
    main()
