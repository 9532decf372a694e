#!/usr/bin/env python3
"""Writes procedural rooms (Tungsten scene.json) for training data or distinct-scene validation.

Why: session 22 (docs/training-log.md) found that the held-out diffuse-interreflection scene's gap
to the 20x target is data: the network reaches it when trained on that room, not on the
training set's five rooms. These are many more rooms of that *kind* (enclosed, lit by area
lights, most of their light indirect), none of them a held-out scene: random size and wall
colours, one to three area lights of random size, power and place (ceiling or wall), one to
six objects (boxes, spheres, blocks) with diffuse, plastic, conductor or textured materials
from train-textures/ (never the held-out scenes' textures/), and a camera inside the room.
With --outside P a room is, with probability P, open at the front and seen from outside
through the opening (the classic Cornell-box view, the walls framing the picture). P = 0
(the default) writes exactly the rooms of earlier sessions: the choice and its camera draw
from a generator of their own.
Every room is a pure function of (seed, index): two seeds give disjoint sets, so one seed
can make training scenes and another distinct validation scenes.

usage: python3 rooms.py --count N --seed S -o DIR [--resolution 160x160] [--prefix room]
                        [--outside P]
writes DIR/<prefix>-<seed>-<i>/scene.json (i = 0..N-1)
"""
import argparse
import json
import math
import os
import random
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from generate import box_room, cam, cube, quad, sphere  # noqa: E402 (the scene helpers)

TEXTURES = ["dots.png", "grass.png", "marble.png", "stripes.png", "tiles.png", "wood.png"]


def colour(r, lo=0.05, hi=0.85, saturated=0.35):
    """An albedo: grey-ish most of the time, a saturated accent with probability `saturated`."""
    if r.random() < saturated:
        c = [r.uniform(lo, 0.3) for _ in range(3)]
        c[r.randrange(3)] = r.uniform(0.45, hi)
        return c
    g = r.uniform(0.25, hi)
    return [min(hi, max(lo, g * r.uniform(0.85, 1.15))) for _ in range(3)]


def material(r, name):
    """One BSDF: mostly diffuse (what indirect light needs), some glossy, some textured."""
    u = r.random()
    if u < 0.45:
        return {"name": name, "type": "lambert", "albedo": colour(r)}
    if u < 0.6:
        return {"name": name, "type": "rough_plastic", "albedo": colour(r), "ior": 1.5,
                "distribution": "ggx", "roughness": r.uniform(0.05, 0.4)}
    if u < 0.7:
        return {"name": name, "type": "rough_conductor", "material": r.choice(["Cu", "Au", "Ag", "Al"]),
                "distribution": "ggx", "roughness": r.uniform(0.08, 0.4)}
    if u < 0.85:
        file = os.path.join(HERE, "train-textures", r.choice(TEXTURES))
        return {"name": name, "type": "lambert", "albedo": {"type": "bitmap", "file": file}}
    res = r.choice([4, 6, 8, 10, 16])
    return {"name": name, "type": "lambert",
            "albedo": {"type": "checker", "on_color": colour(r, saturated=0.2),
                       "off_color": colour(r, hi=0.3, saturated=0.2), "res_u": res, "res_v": res}}


def room(seed, index, resolution, outside=0.0):
    r = random.Random(seed * 1000003 + index)
    # Own stream, so that outside = 0 leaves every draw of r (and so every older room) as it was.
    ro = random.Random((seed * 1000003 + index) * 7919 + 17)
    view_outside = ro.random() < outside
    w, h, d = r.uniform(2, 5), r.uniform(2, 3), r.uniform(2, 5)
    walls = ["floor", "ceil", "back", "left", "right"]
    bs = [{"name": n, "type": "lambert", "albedo": colour(r, saturated=0.4 if n in ("left", "right", "back") else 0.1)}
          for n in walls]
    if r.random() < 0.3 and r.random() < 0.5:  # 15 %: a floor from the objects' materials (textures, gloss)
        bs[0] = material(r, "floor")
    closed = r.random() < 0.5 and not view_outside
    if closed:
        bs.append({"name": "front", "type": "lambert", "albedo": colour(r)})
    bs.append({"name": "light", "type": "null"})
    ps = box_room(w, h, d, *walls, bsdf_front="front" if closed else None)

    # Area lights: total power scaled with the room's surface, so exposure stays in range.
    area = 2 * (w * d + w * h + d * h)
    for _ in range(r.choice([1, 1, 1, 2, 3])):
        s = r.uniform(0.25, 0.7) * min(w, d)
        t = [r.uniform(0.9, 1.0), r.uniform(0.85, 0.95), r.uniform(0.7, 0.9)]
        e = r.uniform(0.2, 0.8) * area / (s * s)
        if r.random() < 0.7:  # ceiling, facing down
            pos = [r.uniform(-0.5, 0.5) * (w - s), h - 0.01, r.uniform(-0.5, 0.5) * (d - s)]
            ps.append(quad("light", pos, [s, 1, s], (0, 0, 180), emission=[e * c for c in t]))
        else:  # high on the back wall, facing into the room
            pos = [r.uniform(-0.5, 0.5) * (w - s), h - s / 2 - 0.05, -d / 2 + 0.01]
            ps.append(quad("light", pos, [s, 1, s], (90, 0, 0), emission=[e * c for c in t]))

    # Objects on the floor, kept off the walls.
    n = r.randint(1, 6)
    for i in range(n):
        name = "obj%d" % i
        bs.append(material(r, name))
        x, z = r.uniform(-0.35, 0.35) * w, r.uniform(-0.45, 0.0) * d
        size = r.uniform(0.12, 0.3) * min(w, d)
        kind = r.random()
        if kind < 0.45:
            ps.append(sphere(name, [x, size / 2, z], size / 2))
        elif kind < 0.85:
            ps.append(cube(name, [x, size / 2, z], [size, size, size], (0, r.uniform(0, 90), 0)))
        else:  # a tall block, like the Cornell box's
            ps.append(cube(name, [x, size, z], [size * 0.7, 2 * size, size * 0.7], (0, r.uniform(0, 90), 0)))

    # Camera just inside the front of the room, looking down into its back half.
    pos = [r.uniform(-0.25, 0.25) * w, r.uniform(0.4, 0.8) * h, d / 2 - r.uniform(0.01, 0.05) * d]
    look = [r.uniform(-0.15, 0.15) * w, r.uniform(0.1, 0.35) * h, -d / 4]
    camera = cam(pos, look, r.uniform(50, 75), resolution)
    if view_outside:
        # In front of the opening, far enough for the opening to about fill the frame.
        fov = ro.uniform(30, 50)
        half = 0.5 * max(w, h) * ro.uniform(0.8, 1.1)
        dist = half / math.tan(math.radians(fov / 2))
        pos = [ro.uniform(-0.1, 0.1) * w, ro.uniform(0.4, 0.6) * h, d / 2 + dist]
        look = [ro.uniform(-0.05, 0.05) * w, ro.uniform(0.4, 0.55) * h, 0]
        camera = cam(pos, look, fov, resolution)
    return {"media": [], "bsdfs": bs, "primitives": ps, "camera": camera,
            "integrator": {"type": "path_tracer", "min_bounces": 0, "max_bounces": 16,
                           "enable_light_sampling": True},
            "renderer": {"spp": 64, "output_file": "room.png"}}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--count", type=int, required=True)
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("-o", dest="out", required=True)
    ap.add_argument("--resolution", default="160x160")
    ap.add_argument("--prefix", default="room")
    ap.add_argument("--outside", type=float, default=0.0,
                    help="probability that a room is open at the front and seen from outside")
    a = ap.parse_args()
    if not 0.0 <= a.outside <= 1.0:
        sys.exit("rooms.py: --outside must be a probability in [0, 1] (got %g)" % a.outside)
    try:
        res = [int(v) for v in a.resolution.lower().split("x")]
        if len(res) != 2 or min(res) < 1:
            raise ValueError
    except ValueError:
        sys.exit("rooms.py: --resolution must be WxH, e.g. 160x160 (got '%s')" % a.resolution)
    if a.count < 1:
        sys.exit("rooms.py: --count must be at least 1")
    for i in range(a.count):
        d = os.path.join(a.out, "%s-%d-%d" % (a.prefix, a.seed, i))
        os.makedirs(d, exist_ok=True)
        with open(os.path.join(d, "scene.json"), "w") as f:
            json.dump(room(a.seed, i, res, a.outside), f, indent=1)
    print("wrote %d rooms to %s" % (a.count, a.out))


if __name__ == "__main__":
    main()
