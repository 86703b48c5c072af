#!/usr/bin/python3
"""scripts/env_stats.py: what is in an environment map, as the preview's IBL sees it.

    /usr/bin/python3 scripts/env_stats.py [MAP ...]   (default: studio blender-city pmndrs-sunset
                                                       from ~/.cache/clothfit/hdri)

Written for issue 12's "Generalises" (docs/fitting.md, "Another environment, on three.js-engine
fits (session 9)"): why velvet fails under blender-city. Per map, printed as one block:
  - size, max luminance, solid-angle-weighted mean luminance, max / median (dynamic range);
  - the share of the map's power (luminance x solid angle) in its brightest texels covering
    0.01 %, 0.1 % and 1 % of the sphere (a sun puts most of the power in the first);
  - the brightest texel's direction (elevation above the horizon, azimuth = u x 360 degrees);
  - the diffuse irradiance of the order-2 SH (SH9, Ramamoorthi & Hanrahan 2001, A_l = pi,
    2 pi / 3, pi / 4) against the exact cosine-weighted integral of the (box-downsampled,
    power-preserving) map, over 2000 Fibonacci normals: relative RMS error (normalised by the
    mean irradiance) and the worst relative error. SH9's clamped-cosine truncation error is
    what the fits' diffuse IBL carries (docs/fitting.md, "The sphere's error decomposed").
Luminance = Rec.709 Y (0.2126, 0.7152, 0.0722). Equirect convention: row 0 = zenith (+Y up),
texel centres at ((i + 0.5) / W, (j + 0.5) / H); solid angle of a texel = (2 pi / W)(pi / H)
sin(theta). Negative texels are clamped to 0, as the renderer does (docs/environments.md).
Needs /usr/bin/python3 with numpy and oiiotool (reads images as scripts/flip_decompose.py does).
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from flip_decompose import read_image  # noqa: E402

Y = np.array([0.2126, 0.7152, 0.0722])


def directions(h, w):
    theta = (np.arange(h) + 0.5) / h * np.pi          # polar angle from +Y
    phi = (np.arange(w) + 0.5) / w * 2.0 * np.pi
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    d = np.stack([st * np.cos(phi)[None, :], np.broadcast_to(ct, (h, w)),
                  st * np.sin(phi)[None, :]], axis=-1)
    dw = (2.0 * np.pi / w) * (np.pi / h) * np.broadcast_to(st, (h, w))
    return d, dw


def sh9(d):
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    return np.stack([0.282095 + 0 * x, 0.488603 * y, 0.488603 * z, 0.488603 * x,
                     1.092548 * x * y, 1.092548 * y * z, 0.315392 * (3 * z * z - 1),
                     1.092548 * x * z, 0.546274 * (x * x - y * y)], axis=-1)


def fibonacci(n):
    i = np.arange(n) + 0.5
    y = 1 - 2 * i / n
    r = np.sqrt(1 - y * y)
    a = np.pi * (3 - np.sqrt(5)) * i
    return np.stack([r * np.cos(a), y, r * np.sin(a)], axis=-1)


def stats(path):
    img = np.maximum(read_image(path, ["R", "G", "B"]).astype(np.float64), 0.0)
    h, w, _ = img.shape
    lum = img @ Y
    d, dw = directions(h, w)
    power = lum * dw
    total = power.sum()
    out = {"size": "%dx%d" % (w, h), "max": lum.max(), "mean": total / (4 * np.pi),
           "max/median": lum.max() / max(np.median(lum), 1e-12)}
    order = np.argsort(lum.ravel())[::-1]
    cum_sa = np.cumsum(dw.ravel()[order])
    cum_p = np.cumsum(power.ravel()[order])
    for frac in (1e-4, 1e-3, 1e-2):
        k = np.searchsorted(cum_sa, frac * 4 * np.pi)
        out["power in top %g%%" % (frac * 100)] = cum_p[k] / total
    j, i = np.unravel_index(order[0], lum.shape)
    out["brightest: elevation deg"] = 90.0 - (j + 0.5) / h * 180.0
    out["brightest: azimuth deg"] = (i + 0.5) / w * 360.0
    # Box-downsample to 256 x 128 (power-preserving: radiance averaged with solid-angle weights).
    f = w // 256
    lw = (lum * dw).reshape(h // f, f, w // f, f).sum(axis=(1, 3))
    sw = dw.reshape(h // f, f, w // f, f).sum(axis=(1, 3))
    ld = lw / sw
    dd, ddw = directions(h // f, w // f)
    n = fibonacci(2000)
    cosines = np.maximum(n @ dd.reshape(-1, 3).T, 0.0)
    exact = cosines @ (ld * ddw).ravel()
    coef = (sh9(dd) * (ld * ddw)[..., None]).reshape(-1, 9).sum(axis=0)
    a = np.array([np.pi] + [2 * np.pi / 3] * 3 + [np.pi / 4] * 5)
    approx = sh9(n) @ (coef * a)
    err = approx - exact
    out["SH9 irradiance: rel RMS"] = np.sqrt(np.mean(err ** 2)) / exact.mean()
    out["SH9 irradiance: worst rel"] = np.max(np.abs(err) / np.maximum(exact, 1e-12 * exact.max()))
    out["irradiance max/min over normals"] = exact.max() / max(exact.min(), 1e-12)
    return out


def main(argv):
    cache = os.path.expanduser("~/.cache/clothfit/hdri")
    maps = argv or ["studio", "blender-city", "pmndrs-sunset"]
    for m in maps:
        path = m if os.path.exists(m) else os.path.join(cache, m + ".exr")
        if not os.path.exists(path):
            sys.exit("env_stats: no map %s (looked for %s)" % (m, path))
        print("== %s (%s)" % (m, path))
        for k, v in stats(path).items():
            print("  %-36s %s" % (k, v if isinstance(v, str) else "%.4g" % v))


if __name__ == "__main__":
    main(sys.argv[1:])
