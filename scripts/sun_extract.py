#!/usr/bin/python3
"""scripts/sun_extract.py: move an environment map's sun into a directional light (measurement).

SUPERSEDED (session 10, s10-sun): the preview and web/ now split a map's sun themselves
(render/scene/sun.{h,cpp}, web/sun.js; docs/sun.md), on by default, or per card with
"environment": {"sun": "auto" | "off"} and `--env-sun` on render-preview / fit / evaluate. This
prototype (a fixed threshold, a 1-texel dilation, modified glTF copies) is kept only to
reproduce session 9's figures (docs/fitting.md "Why velvet fails under blender-city").

    /usr/bin/python3 scripts/sun_extract.py --threshold T OUT_DIR CARD...

Written for issue 12's "Generalises" (docs/fitting.md, "Another environment, on three.js-engine
fits (session 9)"): what would a preview gain if the sun of an HDRI were drawn as a punctual
light (exact BRDF, no prefiltering) instead of through the IBL? For the environment of the
first CARD (all cards must share it):
  1. the sun = the texels with luminance (Rec.709 Y) > T and their 1-texel neighbours;
  2. its irradiance at normal incidence E = sum over those texels of (L - fill) x solid angle,
     per channel, where fill = the median radiance of the ring of texels 2-4 texels around it;
     its direction = the E-luminance-weighted mean direction (the toolkit's equirect
     convention, docs/environments.md: u = atan2(z, x) / 2 pi + 0.5, v = asin(y) / pi + 0.5);
  3. writes OUT_DIR/env_nosun.exr (the sun texels replaced by fill) and, per card, a copy of
     its glTF with one more KHR_lights_punctual directional light "sun" (colour E / max(E),
     intensity max(E) x the card's environment intensity; node rotated so that its -Z axis
     points from the sun to the scene) and a card OUT_DIR/<card name> pointing to both.
The reference is unchanged: the cards are for `clothfit evaluate --scenes` against the
original environment's references. A check (run it): evaluate with --exact-ibl on the new
cards must reproduce --exact-ibl on the original ones up to the Monte Carlo noise.
Needs /usr/bin/python3 with numpy and oiiotool (images as scripts/flip_decompose.py does).
"""
import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from flip_decompose import read_image, write_exr  # noqa: E402

Y = np.array([0.2126, 0.7152, 0.0722])


def dilate(m, k):
    out = m.copy()
    for _ in range(k):
        o = out.copy()
        o[1:, :] |= out[:-1, :]
        o[:-1, :] |= out[1:, :]
        o |= np.roll(out, 1, axis=1) | np.roll(out, -1, axis=1)
        out = o
    return out


def quat_from_to(a, b):
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    c = np.cross(a, b)
    w = 1.0 + float(a @ b)
    q = np.array([c[0], c[1], c[2], w])  # glTF order x, y, z, w
    return q / np.linalg.norm(q)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--threshold", type=float, required=True)
    p.add_argument("out")
    p.add_argument("cards", nargs="+")
    a = p.parse_args()
    os.makedirs(a.out, exist_ok=True)
    card0 = json.load(open(a.cards[0]))
    name = card0["environment"]["path"]
    path = name if os.path.isabs(name) else os.path.expanduser("~/.cache/clothfit/hdri/%s.exr" % name)
    env = np.maximum(read_image(path, ["R", "G", "B"]).astype(np.float64), 0.0)
    h, w, _ = env.shape
    lum = env @ Y
    sun = dilate(lum > a.threshold, 1)
    ring = dilate(sun, 4) & ~dilate(sun, 1)
    fill = np.median(env[ring], axis=0)
    theta = (np.arange(h) + 0.5) / h * np.pi
    dw = (2 * np.pi / w) * (np.pi / h) * np.sin(theta)[:, None] * np.ones((1, w))
    u = (np.arange(w) + 0.5) / w
    phi = (u - 0.5) * 2 * np.pi
    el = np.pi / 2 - theta
    d = np.stack([np.cos(el)[:, None] * np.cos(phi)[None, :], np.sin(el)[:, None] * np.ones((1, w)),
                  np.cos(el)[:, None] * np.sin(phi)[None, :]], axis=-1)
    excess = (env - fill) * dw[..., None]
    e = excess[sun].sum(axis=0)
    wgt = (excess[sun] @ Y)
    sdir = (d[sun] * wgt[:, None]).sum(axis=0)
    sdir /= np.linalg.norm(sdir)
    out_env = env.copy()
    out_env[sun] = fill
    env_path = os.path.join(os.path.abspath(a.out), "env_nosun.exr")
    write_exr(env_path, out_env.astype(np.float32))
    total = (lum * dw).sum()
    print("sun: %d texels, E = %s, luminance share of the map's power %.3f, direction %s "
          "(elevation %.1f deg), fill %s" % (sun.sum(), np.round(e, 4), (e @ Y) / total,
                                             np.round(sdir, 4), np.degrees(np.arcsin(sdir[1])),
                                             np.round(fill, 4)))
    for c in a.cards:
        card = json.load(open(c))
        if card["environment"]["path"] != name:
            sys.exit("sun_extract: %s: environment.path differs from the first card's" % c)
        g = json.load(open(card["gltf"]))
        lights = g.setdefault("extensions", {}).setdefault("KHR_lights_punctual", {}).setdefault("lights", [])
        scale = float(card["environment"].get("intensity", 1.0))
        lights.append({"name": "sun", "type": "directional",
                       "color": [float(x) for x in e / e.max()], "intensity": float(e.max() * scale)})
        q = quat_from_to(np.array([0.0, 0.0, -1.0]), -sdir)
        g["nodes"].append({"name": "sun", "rotation": [float(x) for x in q],
                           "extensions": {"KHR_lights_punctual": {"light": len(lights) - 1}}})
        sc = g["scenes"][g.get("scene", 0)]
        sc["nodes"].append(len(g["nodes"]) - 1)
        base = os.path.splitext(os.path.basename(c))[0]
        gpath = os.path.join(os.path.abspath(a.out), base + "_sun.gltf")
        json.dump(g, open(gpath, "w"))
        card["gltf"] = gpath
        card["environment"]["path"] = env_path
        card["description"] = card.get("description", "") + " [sun as a directional light]"
        json.dump(card, open(os.path.join(a.out, os.path.basename(c)), "w"), indent=2)


if __name__ == "__main__":
    main()
