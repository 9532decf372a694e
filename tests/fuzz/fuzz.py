#!/usr/bin/python3
"""Mutation fuzzing of kpcn's file and command-line inputs.

Every case feeds the tools a damaged input and classifies the outcome. Allowed: success, or a
non-zero exit with a message on stderr and no output file. Failures: a crash (signal or a
sanitizer report), a hang (timeout), a failure that leaves an output file behind, or a
non-zero exit with nothing on stderr, a temporary file left anywhere in WORK, or a rendered or
denoised image with NaN/Inf written on success. Failing cases are kept in WORK/failures/ with the
command line and stderr, and the exit status is 1.

  fuzz.py --bin BUILD/tools --testdata TESTDATA --work DIR [--cases N] [--seed S] TARGET...

Targets (each draws its own mutations from --seed, so a run is reproducible):
  scene  kpcn-render on Tungsten scene JSON with values replaced, deleted, duplicated,
         retyped or truncated (structure-aware); some cases with --albedo-footprint or
         --albedo-spp
  model  kpcntool --denoise:model= on the shipped model with header, architecture,
         metadata, offsets and data damaged, or truncated
  kps    kpcn-train on a small patch store with header words, index records, metadata or
         payload (NaN/Inf) damaged, or truncated
  cli    kpcntool chains of random commands, modifiers and values (--render among them)
  exr    kpcntool (denoise, metrics, info, augment) on AOV EXRs with flipped bytes or truncated
  ckpt   kpcn-render --checkpoint resuming from a damaged checkpoint (raw damage, and damage
         behind a recomputed checksum: row flags, counts, NaN/Inf pixels)
  dataset  kpcn-dataset run and patches on a dataset folder with a damaged plan, manifest,
         variant scene or render, some renders removed

The ctest `fuzz_smoke` runs a few hundred cases; longer runs (--cases 5000) are for
developers (docs/robustness.md records what they found)."""
import argparse
import copy
import json
import os
import random
import re
import shutil
import struct
import subprocess
import sys

BAD = ("CRASH", "TIMEOUT", "PARTIAL", "SILENT", "LEFTOVER", "NONFINITE")


def temp_files(top):
    """Temporaries the tools write before renaming into place (name.tmp.PID, name.partPID.exr)."""
    found = set()
    for d, _, files in os.walk(top):
        if os.path.basename(d) == "failures":
            continue
        found.update(os.path.join(d, f) for f in files if ".tmp." in f or ".part" in f)
    return found


class Fuzzer:
    def __init__(self, args):
        self.a = args
        self.bin = lambda name: os.path.join(args.bin, name, name)
        self.work = os.path.abspath(args.work)
        self.fail_dir = os.path.join(self.work, "failures")
        self.stats = {}
        self.nfail = 0

    def path(self, name):
        return os.path.join(self.work, name)

    def nonfinite(self, exr):
        """True if an image written on success holds NaN/Inf (kpcntool's metrics refuse them)."""
        p = subprocess.run([self.bin("kpcntool"), exr, exr, "--l1"], capture_output=True,
                           text=True, errors="replace", timeout=self.a.timeout)
        return p.returncode != 0 and "NaN/Inf" in p.stderr

    def run(self, target, argv, outputs, keep=(), finite=()):
        """Runs one case; classifies it; keeps the inputs of a failing one. finite: outputs
        that must hold no NaN/Inf when the tool succeeds (a model or image it accepted)."""
        for o in outputs:
            if os.path.isdir(o):
                shutil.rmtree(o)
            elif os.path.exists(o):
                os.remove(o)
        try:
            p = subprocess.run(argv, capture_output=True, text=True, errors="replace",
                               timeout=self.a.timeout, cwd=self.work)
            rc, err = p.returncode, p.stderr
        except subprocess.TimeoutExpired:
            rc, err = None, ""
        left = [o for o in outputs if os.path.exists(o)]
        temps = temp_files(self.work)
        if temps:
            left += sorted(temps)
            for t in temps:
                os.remove(t)
        if rc is None:
            kind = "TIMEOUT"
        elif rc < 0 or "Sanitizer" in err or "runtime error:" in err:
            kind = "CRASH"
        elif temps:
            kind = "LEFTOVER"
        elif rc == 0:
            kind = "NONFINITE" if any(self.nonfinite(o) for o in finite if os.path.exists(o)) \
                else "ok"
        elif left:
            kind = "PARTIAL"
        elif not err.strip():
            kind = "SILENT"
        else:
            kind = "error"
        key = (target, kind)
        self.stats[key] = self.stats.get(key, 0) + 1
        if kind in BAD:
            self.nfail += 1
            os.makedirs(self.fail_dir, exist_ok=True)
            stem = os.path.join(self.fail_dir, "%s_%d_%d" % (target, self.a.seed, self.nfail))
            for k in keep:
                shutil.copy(k, stem + "_" + os.path.basename(k))
            with open(stem + ".txt", "w") as f:
                f.write("%s (exit %s); left behind: %s\n%s\n\n%s\n" %
                        (kind, rc, left, " ".join(repr(x) for x in argv), err[-4000:]))
            print("fuzz: %s %s: %s" % (target, kind, stem + ".txt"), file=sys.stderr)
        return kind


# ---------------------------------------------------------------- scene JSON (kpcn-render)
WEIRD = [0, -1, 1e30, -1e30, float("nan"), float("inf"), 1e-30, 2**31, -2**31, 2**63, "", "x",
         None, True, [], {}, [1], [1, 2], [1, 2, 3, 4], [[1, 2, 3]], "nonexistent.png", 0.5, 3,
         [0, 0, 0], [float("nan")] * 3, [1e30] * 3, {"type": "checker"},
         {"type": "bitmap", "file": "nope.png"}]
TYPES = ["quad", "cube", "sphere", "disk", "mesh", "infinite_sphere", "skydome", "lambert",
         "mirror", "conductor", "rough_conductor", "dielectric", "rough_dielectric", "plastic",
         "rough_plastic", "smooth_coat", "null", "thinlens", "pinhole", "checker", "bitmap",
         "box", "tent", "gaussian", "oren_nayar"]


def json_nodes(x, path=()):
    yield path, x
    if isinstance(x, dict):
        for k, v in x.items():
            yield from json_nodes(v, path + (k,))
    elif isinstance(x, list):
        for i, v in enumerate(x):
            yield from json_nodes(v, path + (i,))


def mutate_json(rng, doc):
    nodes = list(json_nodes(doc))[1:]
    if not nodes:
        return
    path, val = rng.choice(nodes)
    parent = doc
    for p in path[:-1]:
        parent = parent[p]
    key = path[-1]
    r = rng.random()
    if r < 0.35:
        parent[key] = copy.deepcopy(rng.choice(WEIRD))
    elif r < 0.55:
        del parent[key]
    elif r < 0.7 and isinstance(val, str):
        parent[key] = rng.choice(TYPES)
    elif r < 0.85 and isinstance(val, (int, float)) and not isinstance(val, bool):
        parent[key] = val * rng.choice([-1, 0, 1e6, -1e6, 1e-9])
    elif r < 0.92 and isinstance(parent, list):
        parent.append(copy.deepcopy(parent[0]))
    else:
        parent[key] = copy.deepcopy(rng.choice(nodes)[1])


def mirror_scenes(fz):
    """WORK/scenes: the testdata scenes as directories of symlinks, so mutated copies can sit
    next to their originals (relative mesh and texture paths resolve) without writing into
    the source tree."""
    src_dir, dst_dir = os.path.join(fz.a.testdata, "scenes"), fz.path("scenes")
    shutil.rmtree(dst_dir, ignore_errors=True)
    os.makedirs(dst_dir)
    scenes = []
    for d in sorted(os.listdir(src_dir)):
        src = os.path.join(src_dir, d)
        if not os.path.isdir(src):
            os.symlink(src, os.path.join(dst_dir, d))
            continue
        os.makedirs(os.path.join(dst_dir, d))
        for f in sorted(os.listdir(src)):
            os.symlink(os.path.join(src, f), os.path.join(dst_dir, d, f))
            if f.endswith(".json"):
                scenes.append(os.path.join(dst_dir, d, f))
    return scenes


def fuzz_scene(fz, rng, n):
    scenes = mirror_scenes(fz)
    out = fz.path("scene_out.exr")
    for _ in range(n):
        src = rng.choice(scenes)
        with open(src) as f:
            doc = json.load(f)
        for _ in range(rng.randint(1, 3)):
            mutate_json(rng, doc)
        text = json.dumps(doc, allow_nan=True)
        if rng.random() < 0.1:
            text = text[:rng.randrange(len(text) + 1)]
        case = os.path.join(os.path.dirname(src), "fuzz_case.json")
        with open(case, "w") as f:
            f.write(text)
        # the albedo passes read the scene's textures and geometry on their own paths (uv
        # derivatives, per-point camera rays), so damaged scenes go through them too
        extra = rng.choice([[], [], ["--albedo-footprint", str(rng.choice([2, 3, 16]))],
                            ["--albedo-spp", "4"], ["--albedo-footprint", "2", "--albedo-spp", "2"]])
        fz.run("scene", [fz.bin("kpcn-render"), case, "-o", out, "--spp", "1",
                         "--resolution", "24x16", "--threads", "1"] + extra, [out], keep=[case],
               finite=[out])
        os.remove(case)


# ---------------------------------------------------------------- model file (kpcntool)
MODEL_WEIRD = [0, -1, 1, 2**31, 2**32 + 1, 2**62, 1e30, 0.5, "", "x", None, [], {}, [1], [0, 0],
               [48, 36, 3], [48, 36, 3, 3, 1], [0, 36, 3, 3], [-48, 36, 3, 3], "F16", "BF16",
               "I32", "F64"]


def fuzz_model(fz, rng, n):
    with open(os.path.join(fz.a.testdata, "models", "kpcn-cpu.safetensors"), "rb") as f:
        raw = f.read()
    hn = struct.unpack("<Q", raw[:8])[0]
    header0, data0 = json.loads(raw[8:8 + hn]), raw[8 + hn:]
    exr, case, out = fz.path("small.exr"), fz.path("case.safetensors"), fz.path("model_out.exr")
    for _ in range(n):
        h, data = copy.deepcopy(header0), bytearray(data0)
        kind = rng.random()
        if kind < 0.35:  # the architecture JSON inside the metadata
            meta = h["__metadata__"]
            arch = json.loads(meta["kpcn.architecture"])
            k = rng.choice(list(arch))
            if isinstance(arch[k], list) and arch[k] and rng.random() < 0.5:
                arch[k][rng.randrange(len(arch[k]))] = rng.choice(
                    MODEL_WEIRD + [0, 2, 4, 64, 1000, 10**9])
            elif rng.random() < 0.2:
                del arch[k]
            else:
                arch[k] = copy.deepcopy(rng.choice(MODEL_WEIRD))
            meta["kpcn.architecture"] = json.dumps(arch, allow_nan=True)
        elif kind < 0.6:  # one tensor entry
            t = rng.choice([k for k in h if k != "__metadata__"])
            field = rng.choice(["dtype", "shape", "data_offsets", None])
            if field is None:
                del h[t]
            elif field == "data_offsets":
                j = rng.randrange(2)
                o = h[t][field][j]
                h[t][field][j] = rng.choice([0, -8, o + 4, o - 4, len(data) + 4, 2**63, o * 2])
            else:
                h[t][field] = copy.deepcopy(rng.choice(MODEL_WEIRD))
        elif kind < 0.7:  # metadata values
            meta = h["__metadata__"]
            k = rng.choice(list(meta))
            meta[k] = rng.choice(["", "x", "[", "{}", "null", "1e999", "kpcn-model-2", None])
            if meta[k] is None:
                del meta[k]
        elif kind < 0.8:  # weights (NaN and huge values among them)
            for _ in range(rng.randint(1, 8)):
                data[rng.randrange(len(data))] = rng.randrange(256)
        hb = json.dumps(h, allow_nan=True).encode()
        blob = struct.pack("<Q", len(hb)) + hb + bytes(data)
        if kind >= 0.8:  # truncation, header length, header bytes
            r = rng.random()
            if r < 0.5:
                blob = blob[:rng.randrange(len(blob))]
            elif r < 0.7:
                blob = struct.pack("<Q", rng.choice([0, 1, 2**40, 2**63, len(blob), hn - 1])) + blob[8:]
            else:
                blob = bytearray(blob)
                for _ in range(rng.randint(1, 6)):
                    blob[rng.randrange(8, 8 + len(hb))] = rng.randrange(32, 127)
                blob = bytes(blob)
        with open(case, "wb") as f:
            f.write(blob)
        fz.run("model", [fz.bin("kpcntool"), exr, "--denoise:model=" + case, "-o", out], [out],
               keep=[case], finite=[out])


# ---------------------------------------------------------------- patch store (kpcn-train)
def fuzz_kps(fz, rng, n):
    with open(fz.path("small.kps"), "rb") as f:
        raw = f.read()
    index_off, meta_off = struct.unpack("<QQ", raw[40:56])
    case, out = fz.path("case.kps"), fz.path("kps_out.safetensors")
    for _ in range(n):
        b, r = bytearray(raw), rng.random()
        if r < 0.3:  # header words
            for _ in range(rng.randint(1, 3)):
                w = rng.randrange(1, 8)
                old = struct.unpack("<Q", raw[8 * w:8 * w + 8])[0]
                b[8 * w:8 * w + 8] = struct.pack("<Q", rng.choice(
                    [0, 1, 2, 16, 65, 2**31, 2**32, 2**63, len(raw), len(raw) + 32,
                     (old + rng.choice([-32, -1, 1, 32])) % 2**64]))
        elif r < 0.5:  # index records
            for _ in range(rng.randint(1, 4)):
                b[rng.randrange(index_off, meta_off)] = rng.randrange(256)
        elif r < 0.65:  # metadata JSON
            for _ in range(rng.randint(1, 4)):
                b[rng.randrange(meta_off, len(raw))] = rng.choice(b'{}[]",:0123456789-eE.x ')
        elif r < 0.8:  # payload: NaN / Inf float32 words
            for _ in range(rng.randint(1, 20)):
                k = 4096 + 4 * rng.randrange((index_off - 4096) // 4)
                b[k:k + 4] = struct.pack("<f", rng.choice([float("nan"), float("inf"), -1e38]))
        else:
            b = b[:rng.randrange(len(b))]
        with open(case, "wb") as f:
            f.write(bytes(b))
        fz.run("kps", [fz.bin("kpcn-train"), "--store", case, "-o", out, "--preset", "tiny",
                       "--iters", "3", "--batch", "2", "--patch", "16", "--threads", "1", "--quiet",
                       "--ckpt", "", "--csv", "", "--plot", ""], [out], keep=[case])


# ---------------------------------------------------------------- kpcntool command chains
CLI_CMDS = {
    "--augment": ["seed", "index", "shift", "mirror_v", "oneof"], "--colormap": ["map", "max"],
    "--colorswap": ["perm", "all"],
    "--denoise": ["model", "method", "bf16", "tile", "ensemble", "exposure"],
    "--errormap": ["channels", "display", "range", "eps", "allow_nonfinite", "metric"],
    "--info": [], "--kernels": ["model", "branch", "bf16", "tile", "exposure", "firefly"],
    "--l1": ["channels", "display", "range", "eps", "allow_nonfinite"],
    "--mirror": ["dir", "all"], "--mosaic": ["n", "labels", "font", "fontsize"],
    "--mse": ["channels", "eps"], "--ociodisplay": ["display", "view", "config", "from", "looks"],
    "--patches": ["size", "count", "stride", "seed", "cull", "tol", "abs", "importance", "out"],
    "--psnr": ["range", "channels"], "--rell1": ["eps"], "--relmse": ["eps", "channels"],
    "--rotate": ["deg", "all"], "--shift": ["dx", "dy", "all"],
    "--ssim": ["channels", "display", "range"], "--ch": [], "--threads": [], "-o": [],
    "--json": [], "--render": ["spp", "seed", "res", "crop", "albedo_spp", "footprint",
                               "color_only", "max_bounces"]}
CLI_CH = ["R,G,B", "R=albedo.R,G=albedo.G,B=albedo.B", "A=1", "nope", "", "R,R,R,R,R", ",", "=",
          "R=", "=R"]


def fuzz_cli(fz, rng, n):
    model = os.path.join(fz.a.testdata, "models", "kpcn-cpu.safetensors")
    images = [fz.path(f) for f in ("small.exr", "small2.exr", "tiny.exr", "missing.exr", "bad.png")]
    outs = [fz.path(f) for f in ("o.exr", "o.png", "o.jpg", "o.tif", "o.xyz", "p.kps", "pdir")]
    vals = ["0", "1", "-1", "2", "3", "4", "8", "16", "90", "45", "180", "1e9", "-1e9",
            "2147483648", "nan", "inf", "0.5", "", "x", "R,G,B", "color.R", "BRG", "RRR", "h", "v",
            "nlmeans", "bilateral", "foo", model, "/nonexistent.safetensors", "relmse", "ssim",
            "inferno", "sRGB", "ACES", outs[5], outs[6], "a,b,c", "90", "diffuse", "specular",
            "16x12", "0x0", "99999x99999", "0,0,4,4", "4,4,100,1", "1,2,3"]
    scenes = [os.path.join(fz.a.testdata, "scenes", "cornell-box", "scene.json"),
              fz.path("missing.json"), fz.path("small.exr")]
    for _ in range(n):
        argv = [fz.bin("kpcntool")]
        for _ in range(rng.randint(1, 6)):
            if rng.random() < 0.3:
                argv.append(rng.choice(images))
                continue
            c = rng.choice(list(CLI_CMDS))
            mods = CLI_CMDS[c]
            picked = rng.sample(mods, rng.randint(0, min(2, len(mods))))
            arg = c + "".join(":%s=%s" % (m, rng.choice(vals)) for m in picked)
            if rng.random() < 0.05:
                arg += ":bogus=1"
            argv.append(arg)
            if c == "--ch":
                argv.append(rng.choice(CLI_CH))
            elif c == "--threads":
                argv.append(rng.choice(["0", "1", "2", "-3", "x", "100000"]))
            elif c == "-o":
                argv.append(rng.choice(outs[:5] + [fz.path("nodir/o.exr")]))
            elif c == "--render":
                if ":res=" not in arg and rng.random() < 0.8:  # mostly small renders
                    argv[-1] = arg + ":res=16x12"
                argv.append(rng.choice(scenes))
        fz.run("cli", argv, outs)


# ---------------------------------------------------------------- AOV EXR inputs (kpcntool)
def fuzz_exr(fz, rng, n):
    src = fz.path("small.exr")
    with open(src, "rb") as f:
        raw = f.read()
    model = os.path.join(fz.a.testdata, "models", "kpcn-cpu.safetensors")
    case, out = fz.path("case.exr"), fz.path("exr_out.exr")
    for _ in range(n):
        b, r = bytearray(raw), rng.random()
        if r < 0.4:  # header
            for _ in range(rng.randint(1, 6)):
                b[rng.randrange(min(len(b), 1200))] = rng.randrange(256)
        elif r < 0.7:
            for _ in range(rng.randint(1, 10)):
                b[rng.randrange(len(b))] = rng.randrange(256)
        else:
            b = b[:rng.randrange(len(b))]
        with open(case, "wb") as f:
            f.write(bytes(b))
        cmd = rng.choice([["--denoise:model=" + model, "-o", out],
                          ["--denoise:method=nlmeans", "-o", out], [src, "--relmse", "--ssim"],
                          ["--info"], ["--augment:seed=3", "-o", out]])
        fz.run("exr", [fz.bin("kpcntool"), case] + cmd, [out], keep=[case],
               finite=[out] if cmd[0].startswith("--denoise") else [])


# ---------------------------------------------------------------- render checkpoints
CKPT_ARGS = ["--spp", "4", "--resolution", "16x12", "--threads", "1", "--quiet"]


def ckpt_hash(body, rows):
    """render_ckpt.c's checksum: FNV-1a steps per row-flag byte, per u64 count, per float."""
    h, P, M = 0xcbf29ce484222325, 0x100000001b3, 2**64 - 1
    counts = 16 * rows
    for byte in body[:rows]:
        h = ((h ^ byte) * P) & M
    for (v,) in struct.iter_unpack("<Q", body[rows:rows + counts]):
        h = ((h ^ v) * P) & M
    for (v,) in struct.iter_unpack("<I", body[rows + counts:]):
        h = ((h ^ v) * P) & M
    return h


def fuzz_ckpt(fz, rng, n):
    """kpcn-render --checkpoint resuming from damaged checkpoints: raw damage (the checksum's
    business) and, with the checksum made right again, damaged row flags, counts and pixels."""
    with open(fz.path("small.ckpt"), "rb") as f:
        raw = f.read()
    hlen = struct.unpack("<Q", raw[8:16])[0]
    body = 16 + hlen  # row flags, counts, planes, then the 8-byte checksum
    rows = json.loads(raw[16:body])["crop"][3]
    scene = os.path.join(fz.a.testdata, "scenes", "cornell-box", "scene.json")
    case, src, out = fz.path("case.ckpt"), fz.path("case_src.ckpt"), fz.path("ckpt_out.exr")
    for _ in range(n):
        b, r = bytearray(raw), rng.random()
        if r < 0.2:  # anywhere, checksum left as it is
            for _ in range(rng.randint(1, 6)):
                b[rng.randrange(len(b))] = rng.randrange(256)
        elif r < 0.35:  # header JSON or its length
            for _ in range(rng.randint(1, 4)):
                b[rng.randrange(8, body)] = rng.choice(b'{}[]",:0123456789-eE.x ')
        elif r < 0.45:
            b = b[:rng.randrange(len(b))]
        else:  # the body, checksum recomputed: only the loader's own checks stand
            end = len(b) - 8
            for _ in range(rng.randint(1, 8)):
                k = rng.randrange(body, end - 4)
                b[k:k + 4] = rng.choice([struct.pack("<f", rng.choice(
                    [float("nan"), float("inf"), -1e38, 3e38])), struct.pack("<I", 2**32 - 1),
                    bytes([rng.randrange(256)]) * 4])
            b[end:] = struct.pack("<Q", ckpt_hash(bytes(b[body:end]), rows))
        for p in (case, src):
            with open(p, "wb") as f:
                f.write(bytes(b))
        fz.run("ckpt", [fz.bin("kpcn-render"), scene, "-o", out, "--checkpoint", case] + CKPT_ARGS,
               [out], keep=[src], finite=[out])


# ---------------------------------------------------------------- kpcn-dataset folders
def fuzz_dataset(fz, rng, n):
    """kpcn-dataset run and patches on a rendered dataset folder whose plan, manifest, variant
    scene or renders are damaged (some renders removed, so that run has work to do)."""
    base, case = fz.path("ds"), fz.path("ds_case")
    files = [os.path.relpath(os.path.join(d, f), base) for d, _, fs in os.walk(base)
             for f in fs if not f.endswith(".log")]
    store = fz.path("ds_out.kps")
    for _ in range(n):
        shutil.rmtree(case, ignore_errors=True)
        shutil.copytree(base, case, symlinks=True)
        name = rng.choice(files)
        p = os.path.join(case, name)
        with open(p, "rb") as f:
            b = bytearray(f.read())
        if name.endswith(".exr") or rng.random() < 0.3:
            if rng.random() < 0.5 and b:
                b = b[:rng.randrange(len(b))]
            else:
                for _ in range(rng.randint(1, 6)):
                    b[rng.randrange(len(b))] = rng.randrange(256)
        else:  # text: a number made absurd, a key renamed, a line duplicated or cut
            t = b.decode("latin1")
            k = rng.randrange(4)
            if k == 0:
                nums = list(re.finditer(r"-?\d+(\.\d+)?", t))
                if nums:
                    m = rng.choice(nums)
                    t = t[:m.start()] + str(rng.choice(WEIRD[:10])) + t[m.end():]
            elif k == 1:
                keys = list(re.finditer(r'"[a-z_]+":', t))
                if keys:
                    m = rng.choice(keys)
                    t = t[:m.start()] + '"zz' + t[m.start() + 1:]
            elif k == 2:
                lines = t.splitlines(True)
                if lines:
                    i = rng.randrange(len(lines))
                    lines.insert(i, lines[i])
                t = "".join(lines)
            else:
                t = t[:rng.randrange(len(t) + 1)]
            b = bytearray(t.encode("latin1"))
        with open(p, "wb") as f:
            f.write(bytes(b))
        if rng.random() < 0.5:
            shutil.rmtree(os.path.join(case, "renders", "cornell-box"), ignore_errors=True)
        fz.run("dataset", [fz.bin("kpcn-dataset"), "run", case, "--jobs", "1"], [], keep=[p])
        fz.run("dataset", [fz.bin("kpcn-dataset"), "patches", case, "-o", store, "--size", "8",
                           "--per-image", "3", "--allow-partial"], [store], keep=[p])


TARGETS = {"scene": fuzz_scene, "model": fuzz_model, "kps": fuzz_kps, "cli": fuzz_cli,
           "exr": fuzz_exr, "ckpt": fuzz_ckpt, "dataset": fuzz_dataset}


def prepare(fz):
    """Small inputs the targets mutate: AOV renders, a broken PNG, a patch store."""
    os.makedirs(fz.work, exist_ok=True)
    scene = os.path.join(fz.a.testdata, "scenes", "%s", "scene.json")
    for name, sc, res, spp in (("small.exr", "cornell-box", "24x24", "4"),
                               ("small2.exr", "textures", "24x24", "2"),
                               ("tiny.exr", "textures", "3x2", "1")):
        subprocess.run([fz.bin("kpcn-render"), scene % sc, "-o", fz.path(name), "--spp", spp,
                        "--resolution", res, "--threads", "1"], check=True, capture_output=True)
    with open(fz.path("bad.png"), "w") as f:
        f.write("not a png")
    # a checkpoint holding the first row: --time-limit 0 stops one thread after it, without
    # an output (the damaged copies then resume the other rows)
    ck = fz.path("small.ckpt")
    if os.path.exists(ck):
        os.remove(ck)
    subprocess.run([fz.bin("kpcn-render"), scene % "cornell-box", "-o", fz.path("x.exr"),
                    "--checkpoint", ck, "--time-limit", "0"] + CKPT_ARGS, capture_output=True)
    assert os.path.exists(ck), "fuzz: no checkpoint to mutate"
    # a rendered dataset folder: two scenes, one variant, 2 and 8 spp at 16x16
    shutil.rmtree(fz.path("ds"), ignore_errors=True)
    shutil.rmtree(fz.path("ds_scenes"), ignore_errors=True)
    os.makedirs(fz.path("ds_scenes"))
    for sc in ("cornell-box", "textures"):
        os.symlink(os.path.join(fz.a.testdata, "scenes", sc), fz.path(os.path.join("ds_scenes", sc)))
    subprocess.run([fz.bin("kpcn-dataset"), "plan", "--scenes", fz.path("ds_scenes"), "-o",
                    fz.path("ds"), "--variants", "1", "--spp", "2", "--ref-spp", "8",
                    "--resolution", "16x16", "--no-preview", "--split",
                    "train:cornell-box+textures"], check=True, capture_output=True)
    subprocess.run([fz.bin("kpcn-dataset"), "run", fz.path("ds"), "--jobs", "1"], check=True,
                   capture_output=True)
    ds = os.path.join(fz.a.testdata, "dataset")
    subprocess.run([fz.bin("kpcntool"), os.path.join(ds, "sample_noisy.exr"),
                    os.path.join(ds, "sample_ref.exr"),
                    "--patches:size=16:count=6:cull=1:out=" + fz.path("small.kps")],
                   check=True, capture_output=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bin", required=True, help="the build's tools/ directory")
    ap.add_argument("--testdata", required=True)
    ap.add_argument("--work", required=True)
    ap.add_argument("--cases", type=int, default=100, help="cases per target")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=120, help="seconds per case")
    ap.add_argument("targets", nargs="+", choices=sorted(TARGETS))
    a = ap.parse_args()
    # absolute, because WORK/scenes links to the testdata files (a relative testdata path
    # made every link dangle) and the tools run with other working directories
    a.bin, a.testdata, a.work = (os.path.abspath(p) for p in (a.bin, a.testdata, a.work))
    fz = Fuzzer(a)
    prepare(fz)
    for i, t in enumerate(a.targets):
        TARGETS[t](fz, random.Random(a.seed * 1000 + i), a.cases)
    for (t, kind), c in sorted(fz.stats.items()):
        print("fuzz %-6s %-8s %d" % (t, kind, c))
    print("fuzz: %d failing case(s)" % fz.nfail)
    return 1 if fz.nfail else 0


if __name__ == "__main__":
    sys.exit(main())
