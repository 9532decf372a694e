#!/usr/bin/python3
"""The figures the textures-target rules judge a model by (docs/training-log.md, rules 54 and 55).

usage: tools/judge_textures.py MODEL.safetensors TD_DIR [--bin DIR] [--denoise-opts OPTS]
                               [--threads N] [--pairs OUT.tsv] [--baseline BASE.tsv]
       tools/judge_textures.py --compare NEW.tsv BASE.tsv

TD_DIR is a folder tools/training_data.sh built with at least the datasets v1, v2val, v3val,
roomsval, roomsval2 and roomsval3 and v1's 4096-spp references. Prints one JSON object:
  textures        the held-out textures scene, v1's 16-spp render made again with
                  --albedo-footprint 2 (v1's seed for it), denoised, relMSE against the 4096-spp
                  reference; textures_noisy is the footprint render's own relMSE and
                  below_noisy their ratio (issue 6's target: 20x)
  dprime          geometric-mean relMSE of the 36 validation rooms (roomsval, roomsval2,
                  roomsval3) at 16 spp, each rendered again with the footprint
                  (tools/footprint_pairs.sh)
  val32           the same over v2val and v3val, variants 1 and 2 (v000 is the authored scene,
                  which the training stores hold): 32 pairs
  di              the held-out diffuse-interreflection scene, v1's 16-spp render (no texture,
                  so no footprint render) against its 4096-spp reference
  host            the CPU ("cpu", /proc/cpuinfo's model name) and the instruction set its
                  renders and nets ran ("isa", from kpcntool --version: avx512, or avx2 on
                  CPUs without AVX-512 or under an ONEDNN_MAX_CPU_ISA cap below it). Renders differ
                  between the two in their last bits, and a pair's figure by up to a few per
                  cent (docs/renderer.md, "Determinism"): compare models judged on one of them.
Every relMSE is kpcntool's on linear R, G, B. --denoise-opts is appended to
--denoise:model=MODEL (e.g. ':exposure=0.146227151'); by default the model's own recorded
exposure is used. --pairs writes footprint_pairs.sh's line for each of the 68 pairs (its plain
column '-': only the footprint renders are measured). --baseline compares the 68 pairs with
another model's --pairs file and adds "vs_baseline" to the object; --compare does only that, for
two --pairs files (no rendering): how many pairs are better and worse, the ratio of each
group's geometric mean, and the five pairs that lost most and gained most (relMSE ratios).
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

HERE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ROOMS = ["roomsval", "roomsval2", "roomsval3"]
VAL = ["v2val", "v3val"]


def fail(msg):
    sys.exit("judge_textures: " + msg)


def run(cmd, env=None):
    r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    if r.returncode != 0:
        fail("%s failed: %s" % (" ".join(cmd[:3]), r.stderr.strip()))
    return r.stdout


def noisy_jobs(ds, spp):
    """The noisy renders at SPP in dataset DS's manifest (its lines, parsed)."""
    with open(os.path.join(ds, "manifest.jsonl")) as f:
        for line in f:
            j = json.loads(line)
            if j.get("kind") == "noisy" and j.get("spp") == spp:
                yield j


def noisy_entry(ds, scene, spp):
    """v000's noisy render of SCENE at SPP in dataset DS's manifest (its seed and size)."""
    for j in noisy_jobs(ds, spp):
        if j.get("scene") == scene and j.get("variant") == 0:
            return j
    fail("%s/manifest.jsonl has no %d-spp render of %s v000" % (ds, spp, scene))


def pairs_present(ds, variants):
    """How many of dataset DS's 16-spp pairs (of VARIANTS, or all) have both files rendered:
    the pairs tools/footprint_pairs.sh measures."""
    n = 0
    for j in noisy_jobs(ds, 16):
        if variants and j.get("variant") not in variants:
            continue
        noisy = os.path.join(ds, j["out"])
        if os.path.isfile(noisy) and os.path.isfile(noisy[:-len("_16spp.exr")] + "_ref1024spp.exr"):
            n += 1
    return n


def host(tool):
    """The CPU (/proc/cpuinfo's model name) and the instruction set libkpcn, Embree and oneDNN
    run on it, as `kpcntool --version` reports it."""
    model = ""
    try:
        with open("/proc/cpuinfo") as f:
            model = next((l.partition(":")[2].strip() for l in f if l.startswith("model name")), "")
    except OSError:
        pass
    m = re.search(r"instruction set (\w+)", run([tool, "--version"]))
    if not m:
        fail("'%s --version' names no instruction set" % tool)
    return {"cpu": model, "isa": m.group(1)}


def geomean(xs):
    if not xs or min(xs) <= 0:
        fail("a geometric mean over %d figures, one of them <= 0" % len(xs))
    return math.exp(sum(math.log(x) for x in xs) / len(xs))


def read_pairs(path):
    """{(dataset, scene, variant): footprint relMSE} of a --pairs file."""
    out = {}
    try:
        with open(path) as f:
            for n, line in enumerate(f, 1):
                r = line.rstrip("\n").split("\t")
                try:
                    v = float(r[4])
                except (IndexError, ValueError):
                    fail("%s:%d is not a --pairs line (dataset, scene, variant, plain, footprint)"
                         % (path, n))
                if not v > 0 or math.isinf(v):
                    fail("%s:%d: relMSE %s is not positive and finite" % (path, n, r[4]))
                out[tuple(r[:3])] = v
    except OSError as e:
        fail("cannot read '%s': %s" % (path, e.strerror))
    if not out:
        fail("'%s' holds no pairs" % path)
    return out


def compare(new, base):
    """NEW's pairs against BASE's (both from read_pairs; the same pairs)."""
    for k in set(new) ^ set(base):
        fail("pair %s is in only one of the two files" % "/".join(k))
    ratio = {"/".join(k): new[k] / base[k] for k in sorted(new)}
    order = sorted(ratio.items(), key=lambda kv: kv[1])

    def group(names):
        ks = [k for k in new if k[0] in names]
        return geomean([new[k] for k in ks]) / geomean([base[k] for k in ks]) if ks else None

    return {"pairs": len(ratio), "better": sum(r < 1 for r in ratio.values()),
            "worse": sum(r > 1 for r in ratio.values()), "dprime_ratio": group(ROOMS),
            "val32_ratio": group(VAL), "worst": order[::-1][:5], "best": order[:5]}


def main():
    if len(sys.argv) > 1 and sys.argv[1] == "--compare":
        if len(sys.argv) != 4:
            fail("usage: judge_textures.py --compare NEW.tsv BASE.tsv")
        print(json.dumps(compare(read_pairs(sys.argv[2]), read_pairs(sys.argv[3]))))
        return
    ap = kpcn_tools.parser(__doc__)
    ap.add_argument("model")
    ap.add_argument("td")
    ap.add_argument("--bin", default=kpcn_tools.bin_dir())
    ap.add_argument("--denoise-opts", default="")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--pairs")
    ap.add_argument("--baseline")
    a = ap.parse_args()
    base = read_pairs(a.baseline) if a.baseline else None
    tool = os.path.join(a.bin, "kpcntool/kpcntool")
    render = os.path.join(a.bin, "kpcn-render/kpcn-render")
    for exe, what in ((tool, "kpcntool"), (render, "kpcn-render")):
        kpcn_tools.check_executable(exe, what, fail)
    if a.pairs:
        kpcn_tools.check_output(a.pairs, "--pairs", fail)
    if not os.path.isfile(a.model):
        fail("no model file '%s'" % a.model)
    if a.threads < 1:
        fail("--threads must be at least 1")
    dsdir = os.path.join(a.td, "dataset")
    for d in ["v1"] + VAL + ROOMS:
        if not os.path.isfile(os.path.join(dsdir, d, "manifest.jsonl")):
            fail("'%s' has no dataset %s (tools/training_data.sh %s %s)" % (a.td, d, a.td, d))
    v1 = os.path.join(dsdir, "v1")
    refs = {}
    for scene in ("textures", "diffuse-interreflection"):
        refs[scene] = os.path.join(v1, "renders", scene, "v000_ref4096spp.exr")
        if not os.path.isfile(refs[scene]):
            fail("no 4096-spp reference '%s' (tools/training_data.sh renders it after v1)"
                 % refs[scene])
    # v3val's two corridor variants are rejected by the renderer as black (docs/dataset.md):
    # 36 + 32 pairs is the finished rebuild; counted first, before minutes of rendering
    n_rooms = sum(pairs_present(os.path.join(dsdir, d), None) for d in ROOMS)
    n_val = sum(pairs_present(os.path.join(dsdir, d), (1, 2)) for d in VAL)
    if (n_rooms, n_val) != (36, 32):
        fail("expected 36 room pairs and 32 v2val + v3val pairs, found %d and %d (is the rebuild"
             " finished?)" % (n_rooms, n_val))
    denoise = "--denoise:model=" + a.model + a.denoise_opts

    def relmse(img, ref, den=True):
        cmd = [tool, img] + ([denoise] if den else []) + [ref, "--ch", "R,G,B", "--relmse", "--json"]
        return json.loads(run(cmd))["relmse"]

    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        t = noisy_entry(v1, "textures", 16)
        fp = os.path.join(tmp, "textures_fp16.exr")
        run([render, os.path.join(v1, t["scene_file"]), "-o", fp, "--spp", "16", "--seed",
             str(t["seed"]), "--resolution", "%dx%d" % (t["width"], t["height"]), "--threads",
             str(a.threads), "--albedo-footprint", "2", "--quiet"])
        out["textures"] = relmse(fp, refs["textures"])
        out["textures_noisy"] = relmse(fp, refs["textures"], den=False)
        out["below_noisy"] = out["textures_noisy"] / out["textures"]
        d = noisy_entry(v1, "diffuse-interreflection", 16)
        out["di"] = relmse(os.path.join(v1, d["out"]), refs["diffuse-interreflection"])

    env = dict(os.environ, KPCN_BIN=a.bin, THREADS=str(a.threads), K="2", SPP="16",
               DENOISE_OPTS=a.denoise_opts, PLAIN="0")
    fpp = os.path.join(HERE, "tools/footprint_pairs.sh")
    args = [os.path.join(dsdir, d) for d in ROOMS] + [os.path.join(dsdir, d) + ":v001,v002"
                                                      for d in VAL]
    rows = [l.split("\t") for l in run(["bash", fpp, a.model] + args, env=env).splitlines()]
    rooms = [float(r[4]) for r in rows if r[0] in ROOMS]
    val = [float(r[4]) for r in rows if r[0] in VAL]
    if (len(rooms), len(val)) != (36, 32):
        fail("footprint_pairs.sh measured %d room and %d v2val + v3val pairs, not 36 and 32"
             % (len(rooms), len(val)))
    out["dprime"] = geomean(rooms)
    out["val32"] = geomean(val)
    out["host"] = host(tool)
    if a.pairs:
        with open(a.pairs, "w") as f:
            f.write("".join("\t".join(r) + "\n" for r in rows))
    if base is not None:
        out["vs_baseline"] = compare({tuple(r[:3]): float(r[4]) for r in rows}, base)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
