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

def write_png(path, w, h, pixel):
    """8-bit RGB PNG from pixel(x, y) -> (r, g, b) in [0, 1]; stdlib only (no numpy here)."""
    import struct, zlib
    rows = bytearray()
    for y in range(h):
        rows.append(0)
        for x in range(w):
            rows += bytes(max(0, min(255, int(round(c * 255)))) for c in pixel(x, y))
    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
                + chunk(b"IDAT", zlib.compress(bytes(rows), 9)) + chunk(b"IEND", b""))

def value_noise(x, y, period, seed):
    """Tileable smooth value noise in [0, 1] (hash lattice, smoothstep interpolation)."""
    def h(i, j):
        n = ((i % period) * 73856093 ^ (j % period) * 19349663 ^ seed * 83492791) & 0xffffffff
        n = (n ^ (n >> 13)) * 1274126177 & 0xffffffff
        return (n & 0xffff) / 65535.0
    i, j = int(math.floor(x)), int(math.floor(y))
    fx, fy = x - i, y - j
    sx, sy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)
    a = h(i, j) + (h(i + 1, j) - h(i, j)) * sx
    b = h(i, j + 1) + (h(i + 1, j + 1) - h(i, j + 1)) * sx
    return a + (b - a) * sy

def fbm(x, y, period, seed, octaves=4):
    return sum(value_noise(x * 2 ** o, y * 2 ** o, period * 2 ** o, seed + o) / 2 ** (o + 1)
               for o in range(octaves)) / (1 - 0.5 ** octaves)

def training_textures(d):
    """Bitmaps for the dataset-v3 training scenes; none of them appears in a held-out scene."""
    os.makedirs(d, exist_ok=True)
    n = 128
    def tiles(x, y):   # square tiles with grout, per-tile tint
        tx, ty, u, v = x // 16, y // 16, x % 16, y % 16
        if u < 1 or v < 1:
            return (0.3, 0.3, 0.28)
        t = value_noise(tx * 3.1, ty * 1.7, 1 << 20, 5) * 0.15
        return (0.75 - t, 0.72 - t, 0.62 - t)
    def wood(x, y):    # rings along x, grain noise
        r = 10 * fbm(x / 32.0, y / 128.0, 4, 9) + x / 9.0
        k = 0.5 + 0.5 * math.sin(r * 2.2)
        return (0.45 + 0.2 * k, 0.28 + 0.12 * k, 0.12 + 0.06 * k)
    def stripes(x, y):  # fabric: two-colour stripes with a thin accent line
        s = (x + y // 2) % 24
        if s < 2:
            return (0.9, 0.85, 0.2)
        return (0.15, 0.25, 0.55) if s < 13 else (0.8, 0.8, 0.78)
    def dots(x, y):    # polka dots
        u, v = (x % 32) - 16, (y % 32) - 16
        return (0.85, 0.15, 0.2) if u * u + v * v < 64 else (0.9, 0.88, 0.8)
    def marble(x, y):  # veined stone
        t = math.sin(x / 10.0 + 6 * fbm(x / 32.0, y / 32.0, 4, 3))
        k = abs(t) ** 0.3
        return (0.35 + 0.5 * k, 0.35 + 0.48 * k, 0.38 + 0.45 * k)
    def grass(x, y):   # green noise, high frequency
        k = fbm(x / 8.0, y / 8.0, 16, 17)
        return (0.1 + 0.15 * k, 0.25 + 0.35 * k, 0.05 + 0.1 * k)
    for name, fn in (("tiles", tiles), ("wood", wood), ("stripes", stripes), ("dots", dots),
                     ("marble", marble), ("grass", grass)):
        write_png(os.path.join(d, name + ".png"), n, n, fn)

def box_room(w, h, d, bsdf_floor, bsdf_ceil, bsdf_back, bsdf_left, bsdf_right, bsdf_front=None):
    """Box [-w/2,w/2]x[0,h]x[-d/2,d/2], faces pointing inwards; no front wall unless given."""
    ps = [quad(bsdf_floor, [0, 0, 0], [w, 1, d]), quad(bsdf_ceil, [0, h, 0], [w, 1, d], (0, 0, 180)),
          quad(bsdf_back, [0, h / 2, -d / 2], [w, 1, h], (90, 0, 0)),
          quad(bsdf_left, [-w / 2, h / 2, 0], [h, 1, d], (0, 0, -90)),
          quad(bsdf_right, [w / 2, h / 2, 0], [h, 1, d], (0, 0, 90))]
    if bsdf_front:
        ps.append(quad(bsdf_front, [0, h / 2, d / 2], [w, 1, h], (-90, 0, 0)))
    return ps

def table(bsdf, x, z, w, d, h, rot=0):
    c, s = math.cos(math.radians(rot)), math.sin(math.radians(rot))
    ps = [cube(bsdf, [x, h - 0.03, z], [w, 0.06, d], (0, rot, 0))]
    for sx in (-1, 1):
        for sz in (-1, 1):
            lx, lz = sx * (w / 2 - 0.05), sz * (d / 2 - 0.05)
            ps.append(cube(bsdf, [x + c * lx + s * lz, (h - 0.06) / 2, z - s * lx + c * lz],
                           [0.05, h - 0.06, 0.05], (0, rot, 0)))
    return ps

def tex(name, file, kind="lambert", **kw):
    b = {"name": name, "type": kind, "albedo": {"type": "bitmap", "file": "../train-textures/" + file}}
    b.update(kw)
    return b

def training_scenes_v3():
    """Dataset v3 (session 5): eight more training scenes, all different from the held-out
    diffuse-interreflection and textures scenes but rich in what they test: indirect light in
    closed rooms, colour bleeding, textures at several frequencies, many small objects."""
    training_textures(os.path.join(HERE, "train-textures"))
    light = {"name": "light", "type": "null"}

    # living room: accent wall, table, sofa blocks, checker rug, ceiling light
    bs = [lam("beige", [0.7, 0.62, 0.5]), lam("blue", [0.15, 0.25, 0.5]), lam("ceil", [0.8, 0.8, 0.8]),
          tex("wood", "wood.png"), lam("sofa", [0.5, 0.12, 0.1]), light,
          {"name": "rug", "type": "lambert", "albedo": {"type": "checker", "on_color": [0.6, 0.55, 0.3],
                                                       "off_color": [0.2, 0.15, 0.1], "res_u": 6, "res_v": 6}}]
    ps = box_room(4, 2.6, 4, "wood", "ceil", "blue", "beige", "beige")
    ps += [quad("rug", [0.2, 0.005, -0.3], [1.8, 1, 1.3])]
    ps += table("wood", 0.3, -0.3, 1.0, 0.6, 0.45, 15)
    ps += [cube("sofa", [-1.3, 0.25, -0.6], [0.8, 0.5, 1.8]), cube("sofa", [-1.55, 0.55, -0.6], [0.3, 0.6, 1.8]),
           sphere("beige", [1.4, 0.25, -1.4], 0.25),
           quad("light", [0.3, 2.59, 0.0], [0.8, 1, 0.8], (0, 0, 180), emission=[9, 8.5, 7.5])]
    scene("living-room", bs, ps, cam([1.2, 1.5, 1.9], [-0.3, 0.6, -0.8], 60, [160, 120]))

    # closed room lit only through a window: sky and a small "sun" outside
    bs = [lam("wall", [0.75, 0.73, 0.7]), lam("floor", [0.55, 0.45, 0.35]), lam("green", [0.2, 0.5, 0.25]),
          lam("orange", [0.8, 0.4, 0.1]), light]
    w, h, d = 3.0, 2.5, 3.0
    ps = [quad("floor", [0, 0, 0], [w, 1, d]), quad("wall", [0, h, 0], [w, 1, d], (0, 0, 180)),
          quad("wall", [0, h / 2, -d / 2], [w, 1, h], (90, 0, 0)),
          quad("green", [w / 2, h / 2, 0], [h, 1, d], (0, 0, 90)),
          quad("wall", [0, h / 2, d / 2], [w, 1, h], (-90, 0, 0))]
    # left wall (x = -1.5) with a window opening y in [0.6, 2.1], z in [-1.1, 0.9]
    for yc, hh, zc, ww in ((0.3, 0.6, 0, 3.0), (2.3, 0.4, 0, 3.0), (1.35, 1.5, -1.3, 0.4), (1.35, 1.5, 1.2, 0.6)):
        ps.append(quad("wall", [-w / 2, yc, zc], [hh, 1, ww], (0, 0, -90)))
    ps += [cube("orange", [0.6, 0.4, -0.8], [0.8, 0.8, 0.8], (0, 30, 0)), sphere("wall", [-0.3, 0.3, 0.3], 0.3),
           sphere("light", [-9, 6, -1], 0.4, emission=[1600, 1450, 1200]),
           {"type": "infinite_sphere", "emission": [0.9, 1.1, 1.5]}]
    scene("window-room", bs, ps, cam([1.1, 1.3, 1.3], [-0.6, 0.8, -0.6], 65, [160, 120]), max_bounces=24)

    # corridor: long, three small ceiling lights, pillars, strong falloff with depth
    bs = [lam("wall", [0.7, 0.68, 0.6]), lam("floor", [0.4, 0.4, 0.42]), lam("pillar", [0.3, 0.35, 0.6]),
          tex("tiles", "tiles.png"), light]
    ps = box_room(2.0, 2.4, 10, "tiles", "wall", "wall", "wall", "wall")
    for i in range(3):
        ps.append(quad("light", [0, 2.39, 2.5 - 3.2 * i], [0.4, 1, 0.4], (0, 0, 180), emission=[25, 23, 20]))
    for i in range(4):
        for sx in (-1, 1):
            ps.append(cube("pillar", [sx * 0.85, 1.2, 3.0 - 2.4 * i], [0.2, 2.4, 0.2]))
    scene("corridor", bs, ps, cam([0.3, 1.4, 4.8], [-0.1, 1.0, -2], 55, [160, 120]))

    # indirect only: an up-facing light bounces off the ceiling into a coloured room
    bs = [lam("white", [0.8, 0.8, 0.78]), lam("yellow", [0.7, 0.6, 0.15]), lam("blue", [0.1, 0.2, 0.55]),
          tex("marble", "marble.png"), light]
    ps = box_room(3, 2.4, 3, "marble", "white", "white", "yellow", "blue")
    ps += [quad("light", [0, 1.78, -0.6], [0.6, 1, 0.6], emission=[30, 28, 25]),
           cube("white", [0, 0.87, -0.6], [0.3, 1.74, 0.3]), cube("white", [0, 1.76, -0.6], [0.7, 0.02, 0.7]),
           sphere("yellow", [-0.8, 0.35, 0.2], 0.35), cube("white", [0.8, 0.3, 0.0], [0.6, 0.6, 0.6], (0, 40, 0))]
    scene("bounce-light", bs, ps, cam([0.2, 1.3, 2.9], [0, 0.9, -0.5], 60, [160, 160]))

    # textured room: tiles floor, marble wall, wood and dots objects, fine checker panels
    bs = [tex("tiles", "tiles.png"), tex("marble", "marble.png"), tex("wood", "wood.png"),
          tex("dots", "dots.png"), tex("stripes", "stripes.png", "rough_plastic", roughness=0.3, ior=1.5),
          lam("wall", [0.6, 0.62, 0.65]),
          {"name": "fine", "type": "lambert", "albedo": {"type": "checker", "on_color": [0.85, 0.85, 0.85],
                                                        "off_color": [0.1, 0.1, 0.1], "res_u": 32, "res_v": 32}},
          light]
    ps = box_room(3.5, 2.5, 3.5, "tiles", "wall", "marble", "wall", "wall")
    ps += [cube("wood", [-0.7, 0.35, -0.6], [0.7, 0.7, 0.7], (0, 20, 0)), sphere("dots", [0.5, 0.4, -0.3], 0.4),
           cube("stripes", [0.9, 0.25, 0.6], [0.5, 0.5, 0.5], (0, -30, 0)),
           quad("fine", [1.74, 1.2, -0.5], [1.0, 1, 1.0], (0, 0, 90)),
           quad("light", [0.4, 2.49, 0.8], [1.2, 1, 1.2], (0, 0, 180), emission=[6, 6, 5.5])]
    scene("textured-room", bs, ps, cam([-0.4, 1.4, 2.6], [0.2, 0.5, -0.5], 55, [160, 120]))

    # block city: many boxes on grass under sky and a low sun (long hard shadows)
    bs = [tex("grass", "grass.png"), lam("conc", [0.55, 0.55, 0.52]), lam("brick", [0.55, 0.25, 0.18]),
          lam("glassish", [0.25, 0.3, 0.35]), light]
    ps = [quad("grass", [0, 0, 0], [20, 1, 20])]
    for i in range(5):
        for j in range(4):
            hgt = 0.3 + 1.4 * value_noise(i * 1.3, j * 2.1, 1 << 20, 23)
            ps.append(cube(("conc", "brick", "glassish")[(i * 7 + j * 3) % 3],
                           [-2 + i * 1.0, hgt / 2, -2.5 + j * 1.1], [0.6, hgt, 0.6], (0, 10 * ((i + j) % 3), 0)))
    ps += [sphere("light", [8, 3, 4], 0.5, emission=[900, 800, 620]),
           {"type": "infinite_sphere", "emission": [0.35, 0.5, 0.8]}]
    scene("block-city", bs, ps, cam([0.5, 3.0, 4.5], [-0.3, 0.3, -1.0], 50, [160, 120]))

    # shelf: many small coloured boxes and spheres in compartments, side area light
    cols = [[0.7, 0.1, 0.1], [0.1, 0.5, 0.15], [0.15, 0.2, 0.7], [0.8, 0.7, 0.1], [0.6, 0.3, 0.6], [0.8, 0.8, 0.8]]
    bs = [lam("c%d" % i, c) for i, c in enumerate(cols)] + [tex("wood", "wood.png"), lam("wall", [0.5, 0.5, 0.5]), light]
    ps = [quad("wall", [0, 0, 0], [6, 1, 6]), quad("wall", [0, 1.5, -0.5], [6, 1, 3], (90, 0, 0))]
    for k in range(4):
        ps.append(cube("wood", [0, 0.05 + 0.5 * k, -0.25], [2.0, 0.04, 0.45]))
    for sx in (-1, 0, 1):
        ps.append(cube("wood", [sx * 1.0, 0.78, -0.25], [0.04, 1.56, 0.45]))
    for k in range(3):
        for i in range(8):
            u = value_noise(i * 1.7, k * 3.3, 1 << 20, 31)
            c = "c%d" % ((i * 5 + k * 2) % 6)
            x, y = -0.9 + i * 0.25, 0.07 + 0.5 * k
            if u < 0.5:
                hh = 0.12 + 0.25 * u
                ps.append(cube(c, [x, y + hh / 2, -0.2], [0.14, hh, 0.2], (0, 40 * u, 0)))
            else:
                ps.append(sphere(c, [x, y + 0.08, -0.15], 0.08))
    ps.append(quad("light", [-2.2, 1.2, 1.0], [1.0, 1, 1.0], (0, 0, -60), emission=[14, 13, 12]))
    scene("shelf", bs, ps, cam([0.2, 0.9, 2.4], [0, 0.75, -0.2], 50, [160, 120]))

    # patterned objects under the environment map: stripes, dots, fine checker, marble
    bs = [tex("marble", "marble.png"), tex("stripes", "stripes.png"), tex("dots", "dots.png", "plastic", ior=1.5),
          {"name": "fine", "type": "lambert", "albedo": {"type": "checker", "on_color": [0.7, 0.7, 0.2],
                                                        "off_color": [0.1, 0.1, 0.3], "res_u": 24, "res_v": 12}},
          tex("tiles", "tiles.png")]
    ps = [quad("tiles", [0, 0, 0], [6, 1, 6]), sphere("stripes", [-0.7, 0.35, 0], 0.35),
          sphere("fine", [0.1, 0.3, -0.5], 0.3), cube("dots", [0.7, 0.3, 0.1], [0.6, 0.6, 0.6], (0, 35, 0)),
          cube("marble", [-0.2, 0.15, 0.6], [0.5, 0.3, 0.3], (0, -15, 0)),
          {"type": "infinite_sphere", "emission": "../materialtest/envmap.hdr", "sample": True,
           "transform": {"rotation": [0, 150, 0]}}]
    scene("patterns-envmap", bs, ps, cam([0.3, 1.3, 3.0], [0, 0.3, 0], 45, [160, 120], filt="tent"))

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
    training_scenes_v3()
