#!/usr/bin/env python3
"""Writes kpcn's own test scenes (Tungsten scene.json format) into this folder.

Each scene is small (128-192 px) and exercises what a denoiser must learn; docs/renderer.md
lists them. Re-run to regenerate; textures are made with oiiotool, the OBJ mesh here.
Usage: python3 generate.py   (from any directory)
"""
import json, math, os, subprocess

HERE = os.path.dirname(os.path.abspath(__file__))

def cam(pos, look, fov, res, filt="box", **kw):
    c = {"type": "pinhole", "resolution": res, "fov": fov, "reconstruction_filter": filt,
         "transform": {"position": pos, "look_at": look, "up": [0, 1, 0]}}
    c.update(kw)
    return c

def scene(name, bsdfs, prims, camera, spp=64, max_bounces=16):
    doc = {"media": [], "bsdfs": bsdfs, "primitives": prims, "camera": camera,
           "integrator": {"type": "path_tracer", "min_bounces": 0, "max_bounces": max_bounces,
                          "enable_light_sampling": True},
           "renderer": {"spp": spp, "output_file": name + ".png"}}
    d = os.path.join(HERE, name)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, "scene.json"), "w") as f:
        json.dump(doc, f, indent=1)

def quad(bsdf, pos, scale, rot=(0, 0, 0), **kw):
    p = {"type": "quad", "bsdf": bsdf, "transform": {"position": pos, "scale": scale, "rotation": list(rot)}}
    p.update(kw)
    return p

def cube(bsdf, pos, scale, rot=(0, 0, 0), **kw):
    p = {"type": "cube", "bsdf": bsdf, "transform": {"position": pos, "scale": scale, "rotation": list(rot)}}
    p.update(kw)
    return p

def sphere(bsdf, pos, r, **kw):
    p = {"type": "sphere", "bsdf": bsdf, "transform": {"position": pos, "scale": r}}
    p.update(kw)
    return p

def lam(name, a):
    return {"name": name, "type": "lambert", "albedo": a}

def room(light_emission, light_scale, extra_bsdfs=()):
    """Open-front box [-1,1]x[0,2]x[-1,1] with a ceiling light facing down."""
    bs = [lam("white", [0.75, 0.75, 0.72]), lam("red", [0.6, 0.08, 0.06]),
          lam("green", [0.12, 0.45, 0.1]), {"name": "light", "type": "null"}] + list(extra_bsdfs)
    ps = [quad("white", [0, 0, 0], [2, 1, 2]),
          quad("white", [0, 2, 0], [2, 1, 2], (0, 0, 180)),
          quad("white", [0, 1, -1], [2, 1, 2], (90, 0, 0)),
          quad("red", [-1, 1, 0], [2, 1, 2], (0, 0, -90)),
          quad("green", [1, 1, 0], [2, 1, 2], (0, 0, 90)),
          quad("light", [0, 1.99, 0], light_scale, (0, 0, 180), emission=light_emission)]
    return bs, ps

def main():
    # 1. diffuse interreflection, large area light, soft shadows
    bs, ps = room([4, 4, 3.6], [1.4, 1, 1.4])
    ps += [cube("white", [-0.35, 0.5, -0.3], [0.5, 1.0, 0.5], (0, 25, 0)),
           sphere("white", [0.4, 0.35, 0.25], 0.35)]
    scene("diffuse-interreflection", bs, ps, cam([0, 1, 4.2], [0, 1, 0], 40, [160, 160]))

    # 2. glossy + mirror, small light
    bs, ps = room([30, 28, 24], [0.3, 1, 0.3], [
        {"name": "gold", "type": "rough_conductor", "material": "Au", "distribution": "ggx", "roughness": 0.08},
        {"name": "silver", "type": "rough_conductor", "material": "Ag", "distribution": "beckmann", "roughness": 0.3},
        {"name": "mirror", "type": "mirror", "albedo": 0.95},
        {"name": "redplastic", "type": "rough_plastic", "albedo": [0.7, 0.1, 0.1], "roughness": 0.15, "ior": 1.5}])
    ps[2]["bsdf"] = "mirror"
    ps += [sphere("gold", [-0.5, 0.3, 0.1], 0.3), sphere("silver", [0.0, 0.3, -0.3], 0.3),
           sphere("redplastic", [0.5, 0.3, 0.2], 0.3)]
    scene("glossy-mirror", bs, ps, cam([0, 1, 4.2], [0, 0.9, 0], 40, [160, 160]))

    # 3. glass and caustics, hard light from a small disk
    bs = [lam("floor", [0.7, 0.7, 0.7]), lam("wall", [0.5, 0.55, 0.6]),
          {"name": "glass", "type": "dielectric", "ior": 1.5},
          {"name": "frosted", "type": "rough_dielectric", "ior": 1.45, "roughness": 0.15, "distribution": "ggx"},
          {"name": "light", "type": "null"}]
    ps = [quad("floor", [0, 0, 0], [6, 1, 6]), quad("wall", [0, 2, -2], [6, 1, 6], (90, 0, 0)),
          sphere("glass", [-0.45, 0.45, 0], 0.45),
          cube("frosted", [0.6, 0.35, -0.2], [0.5, 0.7, 0.5], (0, 30, 0)),
          # a disk emits along its local y axis (Tungsten): tilt it towards the objects
          {"type": "disk", "bsdf": "light", "emission": [500, 460, 400],
           "transform": {"position": [-0.8, 3.0, 1.0], "scale": 0.15, "rotation": [-160, 0, 0]}}]
    scene("glass-caustics", bs, ps, cam([0, 1.3, 3.5], [0, 0.4, 0], 45, [160, 120]))

    # 4. textures: checker + bitmaps
    tex = os.path.join(HERE, "textures")
    os.makedirs(tex, exist_ok=True)
    subprocess.run(["oiiotool", "--pattern", "checker:width=8:height=4:color1=0.55,0.2,0.12:color2=0.85,0.75,0.6",
                    "64x64", "3", "--pattern", "noise:type=uniform:min=0:max=0.15:mono=1", "64x64", "3", "--add",
                    "-d", "uint8", "-o", os.path.join(tex, "bricks.png")], check=True)
    subprocess.run(["oiiotool", "--pattern",
                    "fill:topleft=0.9,0.2,0.1:topright=0.1,0.8,0.2:bottomleft=0.1,0.2,0.9:bottomright=0.9,0.9,0.1",
                    "32x32", "3", "-d", "uint8", "-o", os.path.join(tex, "gradient.png")], check=True)
    bs = [{"name": "checker", "type": "lambert", "albedo": {"type": "checker", "on_color": [0.8, 0.8, 0.8],
                                                          "off_color": [0.15, 0.15, 0.2], "res_u": 12, "res_v": 12}},
          {"name": "bricks", "type": "lambert", "albedo": "../textures/bricks.png"},
          {"name": "gradient", "type": "rough_plastic", "albedo": {"type": "bitmap", "file": "../textures/gradient.png"},
           "roughness": 0.2},
          {"name": "light", "type": "null"}]
    ps = [quad("checker", [0, 0, 0], [4, 1, 4]), quad("bricks", [0, 1, -1.2], [4, 1, 2], (90, 0, 0)),
          cube("gradient", [-0.5, 0.3, 0], [0.6, 0.6, 0.6], (0, 35, 0)), sphere("bricks", [0.55, 0.35, 0.2], 0.35),
          quad("light", [0, 2.5, 0.8], [1.5, 1, 1.5], (0, 0, 180), emission=[5, 5, 5])]
    scene("textures", bs, ps, cam([0, 1.2, 3.2], [0, 0.5, 0], 45, [160, 120]))

    # 5. thin geometry: bars and wires in front of a lit wall
    bs = [lam("wall", [0.7, 0.7, 0.7]), lam("bar", [0.3, 0.25, 0.2]),
          {"name": "wire", "type": "rough_conductor", "material": "Cu", "roughness": 0.2}, {"name": "light", "type": "null"}]
    ps = [quad("wall", [0, 0, 0], [4, 1, 4]), quad("wall", [0, 1.5, -1], [4, 1, 3], (90, 0, 0))]
    for i in range(11):
        ps.append(cube("bar", [-1.0 + 0.2 * i, 0.8, -0.3], [0.015, 1.6, 0.015]))
    for j in range(5):
        ps.append(cube("wire", [0, 0.2 + 0.3 * j, 0.1], [2.2, 0.006, 0.006], (0, 0, 3 * j)))
    ps.append(quad("light", [0.5, 2.6, 1.0], [0.6, 1, 0.6], (30, 0, 180), emission=[18, 17, 15]))
    scene("thin-geometry", bs, ps, cam([0, 0.9, 3.0], [0, 0.8, 0], 45, [160, 120]))

    # 6. environment lighting (materialtest's envmap), OBJ mesh through assimp
    obj = os.path.join(HERE, "meshes")
    os.makedirs(obj, exist_ok=True)
    write_icosphere(os.path.join(obj, "icosphere.obj"), 2)
    bs = [lam("floor", [0.6, 0.6, 0.6]),
          {"name": "blueplastic", "type": "plastic", "albedo": [0.1, 0.2, 0.6], "ior": 1.5},
          {"name": "chrome", "type": "mirror", "albedo": 0.9},
          {"name": "coat", "type": "smooth_coat", "ior": 1.5, "thickness": 1, "sigma_a": [0.0, 0.1, 0.3],
           "substrate": {"type": "lambert", "albedo": [0.8, 0.8, 0.8]}}]
    ps = [{"type": "disk", "bsdf": "floor", "transform": {"position": [0, 0, 0], "scale": 3}},
          {"type": "mesh", "file": "../meshes/icosphere.obj", "bsdf": "blueplastic", "smooth": True,
           "transform": {"position": [-0.6, 0.4, 0], "scale": 0.4}},
          sphere("chrome", [0.3, 0.35, -0.5], 0.35), sphere("coat", [0.55, 0.3, 0.4], 0.3),
          {"type": "infinite_sphere", "emission": "../materialtest/envmap.hdr", "sample": True,
           "transform": {"rotation": [0, 40, 0]}}]
    scene("envmap-lighting", bs, ps, cam([0, 1.2, 3.2], [0, 0.35, 0], 40, [160, 120], filt="tent"))

    # 7. depth discontinuities: staircase under a thin-lens camera
    bs = [lam("step", [0.65, 0.6, 0.55]), lam("back", [0.3, 0.35, 0.5]), {"name": "light", "type": "null"}]
    ps = [quad("back", [0, 0, -3], [8, 1, 8]), quad("back", [0, 2, -4], [8, 1, 8], (90, 0, 0))]
    for i in range(6):
        ps.append(cube("step", [-1.2 + 0.5 * i, 0.15 + 0.2 * i, -0.6 * i], [0.45, 0.3 + 0.4 * i, 0.5]))
    ps.append(sphere("light", [1.0, 3.0, 1.5], 0.25, emission=[200, 185, 165]))
    scene("depth-discontinuities", bs, ps,
          dict(cam([0, 1.4, 4.0], [0, 0.6, -1], 45, [160, 120]), type="thinlens", focus_distance=4.3,
               aperture_size=0.05))

    # 8. hard and soft shadows: tiny sphere light + large quad light
    bs = [lam("floor", [0.75, 0.75, 0.75]), lam("pillar", [0.5, 0.5, 0.55]), {"name": "light", "type": "null"}]
    ps = [quad("floor", [0, 0, 0], [6, 1, 6]), quad("floor", [0, 1.5, -1.5], [6, 1, 3], (90, 0, 0))]
    for i in range(4):
        ps.append(cube("pillar", [-0.9 + 0.6 * i, 0.4, -0.2 + 0.15 * i], [0.15, 0.8, 0.15]))
    ps.append(sphere("light", [-1.5, 2.0, 1.0], 0.04, emission=[900, 800, 650]))
    ps.append(quad("light", [1.5, 2.0, 1.5], [1.5, 1, 1.5], (0, 0, 135), emission=[1.5, 2.0, 3.0]))
    scene("hard-soft-shadows", bs, ps, cam([0, 1.5, 3.5], [0, 0.4, 0], 45, [160, 120], filt="gaussian"))

    # 9. constant background (sky) and plastics, gaussian filter
    bs = [lam("ground", [0.4, 0.35, 0.3]), {"name": "p1", "type": "plastic", "albedo": [0.8, 0.5, 0.1]},
          {"name": "p2", "type": "rough_plastic", "albedo": [0.2, 0.6, 0.3], "roughness": 0.3},
          {"name": "cu", "type": "conductor", "material": "Cu"}]
    ps = [quad("ground", [0, 0, 0], [10, 1, 10]), sphere("p1", [-0.7, 0.35, 0], 0.35),
          sphere("p2", [0.0, 0.35, -0.4], 0.35), sphere("cu", [0.7, 0.35, 0], 0.35),
          {"type": "infinite_sphere", "emission": [0.6, 0.75, 1.0]}]
    scene("sky-plastics", bs, ps, cam([0, 1.0, 3.0], [0, 0.35, 0], 40, [160, 120], filt="gaussian"))

def extra_scenes():
    # 10. textured emitter: a bitmap "screen" lighting a dark room, checker-textured floor light
    bs = [lam("wall", [0.6, 0.6, 0.6]), {"name": "screen", "type": "null"},
          {"name": "glossy", "type": "rough_conductor", "material": "Al", "roughness": 0.25}]
    ps = [quad("wall", [0, 0, 0], [6, 1, 6]), quad("wall", [0, 1.5, -1.5], [6, 1, 3], (90, 0, 0)),
          quad("screen", [0, 0.9, -1.45], [1.6, 1, 0.9], (90, 0, 0),
               emission={"type": "bitmap", "file": "../textures/gradient.png"}),
          sphere("glossy", [-0.6, 0.3, -0.3], 0.3), cube("wall", [0.6, 0.25, -0.4], [0.4, 0.5, 0.4], (0, 20, 0)),
          {"type": "disk", "bsdf": "screen", "transform": {"position": [0.8, 2.2, 0.8], "scale": 0.4,
                                                          "rotation": [0, 0, 180]},
           "emission": {"type": "checker", "on_color": [3, 3, 3], "off_color": [0.3, 0.3, 0.3],
                        "res_u": 8, "res_v": 4}}]
    scene("textured-emitters", bs, ps, cam([0, 1.1, 3.0], [0, 0.6, -0.5], 45, [160, 120]))

def write_icosphere(path, subdiv):
    t = (1 + 5 ** 0.5) / 2
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
         (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2), (10, 7, 6),
         (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10),
         (8, 6, 7), (9, 8, 1)]
    v = [tuple(c / math.sqrt(sum(x * x for x in p)) for c in p) for p in v]
    for _ in range(subdiv):
        cache, nf = {}, []
        def mid(a, b):
            k = (min(a, b), max(a, b))
            if k not in cache:
                m = [(v[a][i] + v[b][i]) / 2 for i in range(3)]
                n = math.sqrt(sum(x * x for x in m))
                v.append(tuple(x / n for x in m))
                cache[k] = len(v) - 1
            return cache[k]
        for a, b, c in f:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            nf += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        f = nf
    with open(path, "w") as o:
        o.write("# icosphere, subdivision %d, written by generate.py\n" % subdiv)
        for p in v:
            o.write("v %.6f %.6f %.6f\n" % p)
        for p in v:
            o.write("vn %.6f %.6f %.6f\n" % p)
        for a, b, c in f:
            o.write("f %d//%d %d//%d %d//%d\n" % (a + 1, a + 1, b + 1, b + 1, c + 1, c + 1))

if __name__ == "__main__":
    main()
    extra_scenes()
