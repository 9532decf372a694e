#!/usr/bin/env python3
"""Writes the 1D LUTs of kpcn's default OCIO config (config.ocio, same folder).

The tone-mapped views first map scene-linear x >= 0 to t in [0,1] with the config's
LogAffineTransform  t = (log2(x + 2^-14) + 14) / 20  (20 stops, x = 0 -> t = 0,
x = 2^6 - 2^-14 -> t = 1), then look up one of these LUTs, which hold
  display = sRGB_OETF(tone(x(t))),   x(t) = 2^(20 t - 14) - 2^-14.
Tone curves:
  reinhard.spi1d  tone(x) = x / (1 + x)
  filmic.spi1d    Hable's filmic curve (Uncharted 2), exposure bias 2, white point 11.2
Run: python3 testdata/ocio/make_luts.py   (pure Python, deterministic)
"""
import os

N = 4096


def srgb(v):
    v = min(max(v, 0.0), 1.0)
    return 12.92 * v if v <= 0.0031308 else 1.055 * v ** (1 / 2.4) - 0.055


def x_of_t(t):
    return 2.0 ** (20.0 * t - 14.0) - 2.0 ** -14


def reinhard(x):
    return x / (1.0 + x)


def hable(x):
    A, B, C, D, E, F = 0.15, 0.50, 0.10, 0.20, 0.02, 0.30
    return ((x * (A * x + C * B) + D * E) / (x * (A * x + B) + D * F)) - E / F


def filmic(x):
    return hable(2.0 * x) / hable(11.2)


def write(name, tone):
    here = os.path.dirname(os.path.abspath(__file__))
    with open(os.path.join(here, name), "w") as f:
        f.write("Version 1\nFrom 0.0 1.0\nLength %d\nComponents 1\n{\n" % N)
        for i in range(N):
            f.write("  %.9f\n" % srgb(tone(x_of_t(i / (N - 1)))))
        f.write("}\n")


write("reinhard.spi1d", reinhard)
write("filmic.spi1d", filmic)
