#!/usr/bin/env python3
"""Writes a catalogue of captured-style fabric materials in every input format of
`clothfit convert` (docs/convert.md), plus a handful of deliberately broken entries.

    python3 datasets/catalogue/generate.py --out /tmp/catalogue [--count 200] [--seed 1]

Layout (COUNT materials per analytic format; measured and woven ones are fewer: MERL tables
are large and woven BSDFs are slow to average):

    presets/   clothfit.preset v1 files (cloth, physical-sheen, standard, gltf-sheen)
    gltf/      glTF 2.0 (.gltf and .glb; 1-4 materials per file; KHR_materials_sheen,
               KHR_materials_specular; some with base colour / normal / metallic-roughness maps)
    seed/      seed.SurfaceMaterial v1 (some with maps)
    stacks/    seed.TextureStack v1 folders (front and back sides, optical-capture maps)
    merl/      MERL-format binary tables (16 x 16 x 32 cells, a cloth sheen + Lambert +
               optional GGX lobe with 1 % multiplicative noise)
    fabrics/   clothfit-fabric definitions (the repository's weaves, copied to weaves/)
    broken/    the broken entries, each named after what is wrong with it

Deterministic for a given --seed. Standard library only.
"""
import argparse
import json
import math
import os
import random
import shutil
import struct
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))
DATASETS = os.path.dirname(HERE)


def png(path, w, h, pixel):
    """8-bit RGB PNG; pixel(x, y) -> (r, g, b) in 0..255."""
    raw = b"".join(b"\x00" + bytes(sum((list(pixel(x, y)) for x in range(w)), []))
                   for y in range(h))

    def chunk(tag, data):
        c = struct.pack(">I", len(data)) + tag + data
        return c + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n")
        f.write(chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)))
        f.write(chunk(b"IDAT", zlib.compress(raw)))
        f.write(chunk(b"IEND", b""))


def srgb8(lin):
    s = lin * 12.92 if lin <= 0.0031308 else 1.055 * lin ** (1 / 2.4) - 0.055
    return max(0, min(255, int(round(s * 255))))


def fabric_colour(rng):
    """A dyed-fabric colour (linear sRGB): a hue, moderate saturation, albedo 0.03-0.7."""
    h = rng.random()
    s = rng.uniform(0.1, 0.8)
    v = rng.uniform(0.15, 0.85)
    i = int(h * 6)
    f = h * 6 - i
    p, q, t = v * (1 - s), v * (1 - s * f), v * (1 - s * (1 - f))
    r, g, b = [(v, t, p), (q, v, p), (p, v, t), (p, q, v), (t, p, v), (v, p, q)][i % 6]
    return [round(srgb_to_lin(c), 4) for c in (r, g, b)]


def srgb_to_lin(s):
    return s / 12.92 if s <= 0.04045 else ((s + 0.055) / 1.055) ** 2.4


def write_json(path, obj):
    with open(path, "w") as f:
        json.dump(obj, f, indent=1)
        f.write("\n")


def colour_map(path, rng, base):
    """A 8x8 woven-looking colour map around `base` (linear), stored sRGB."""
    def px(x, y):
        k = 0.8 + 0.4 * (((x + y) % 2) ^ (x // 2 % 2))
        return tuple(srgb8(min(1.0, c * k)) for c in base)
    png(path, 8, 8, px)


def normal_map(path):
    png(path, 8, 8, lambda x, y: (128 + (20 if x % 2 else -20), 128 + (20 if y % 2 else -20), 240))


def grey_map(path, value):
    v = max(0, min(255, int(round(value * 255))))
    png(path, 4, 4, lambda x, y: (v, v, v))


def presets(out, rng, n):
    d = os.path.join(out, "presets")
    os.makedirs(d)
    for i in range(n):
        model = ["cloth", "cloth", "physical-sheen", "standard", "gltf-sheen"][i % 5]
        c = fabric_colour(rng)
        p = {"base_color": c, "roughness": round(rng.uniform(0.3, 1.0), 3)}
        if model == "cloth":
            p["sheen_color"] = [round(min(1, x ** 0.5 * rng.uniform(0.8, 1.1)), 4) for x in c]
        elif model in ("physical-sheen", "gltf-sheen"):
            p["sheen_color"] = [round(rng.uniform(0.2, 1.0), 3)] * 3
            p["sheen_roughness"] = round(rng.uniform(0.2, 0.9), 3)
        write_json(os.path.join(d, "preset_%04d.json" % i),
                   {"schema": "clothfit.preset", "version": 1, "model": model, "parameters": p})


def gltf_material(rng, i, textures):
    c = fabric_colour(rng)
    m = {"name": "fabric_%d" % i,
         "pbrMetallicRoughness": {"baseColorFactor": c + [1.0],
                                  "roughnessFactor": round(rng.uniform(0.4, 1.0), 3),
                                  "metallicFactor": 0.0}}
    ext = {}
    if rng.random() < 0.75:
        ext["KHR_materials_sheen"] = {
            "sheenColorFactor": [round(min(1, x ** 0.5), 3) for x in c],
            "sheenRoughnessFactor": round(rng.uniform(0.25, 0.9), 3)}
    if rng.random() < 0.2:
        ext["KHR_materials_specular"] = {"specularFactor": round(rng.uniform(0.2, 1.0), 3)}
    if ext:
        m["extensions"] = ext
    if textures is not None:
        m["pbrMetallicRoughness"]["baseColorTexture"] = {"index": textures[0]}
        m["normalTexture"] = {"index": textures[1]}
        m["pbrMetallicRoughness"]["metallicRoughnessTexture"] = {"index": textures[2]}
    return m, sorted(ext)


def gltf(out, rng, n):
    d = os.path.join(out, "gltf")
    os.makedirs(os.path.join(d, "textures"))
    made, f = 0, 0
    while made < n:
        k = min(n - made, rng.choice([1, 1, 2, 4]))
        doc = {"asset": {"version": "2.0", "generator": "clothfit catalogue"}, "materials": []}
        used = set()
        with_maps = f % 5 == 0
        if with_maps:
            base = "t%03d" % f
            colour_map(os.path.join(d, "textures", base + "_albedo.png"), rng, [0.6, 0.6, 0.6])
            normal_map(os.path.join(d, "textures", base + "_normal.png"))
            png(os.path.join(d, "textures", base + "_mr.png"), 4, 4,
                lambda x, y: (255, 150 + 10 * x, 0))
            doc["images"] = [{"uri": "textures/%s_%s.png" % (base, s)} for s in ("albedo", "normal", "mr")]
            doc["textures"] = [{"source": 0}, {"source": 1}, {"source": 2}]
        for j in range(k):
            m, ext = gltf_material(rng, made + j, [0, 1, 2] if with_maps else None)
            used.update(ext)
            doc["materials"].append(m)
        if used:
            doc["extensionsUsed"] = sorted(used)
        if f % 7 == 3 and not with_maps:
            glb(os.path.join(d, "file_%04d.glb" % f), doc)
        else:
            write_json(os.path.join(d, "file_%04d.gltf" % f), doc)
        made += k
        f += 1


def glb(path, doc):
    js = json.dumps(doc).encode()
    js += b" " * ((4 - len(js) % 4) % 4)
    with open(path, "wb") as fh:
        fh.write(struct.pack("<III", 0x46546C67, 2, 12 + 8 + len(js)))
        fh.write(struct.pack("<II", len(js), 0x4E4F534A))
        fh.write(js)


SHARED_BRDFS = ["cloth", "physical-sheen", "gltf-sheen", "standard"]


def shared_params(rng, brdf):
    c = fabric_colour(rng)
    p = {"color": c, "roughness": round(rng.uniform(0.35, 1.0), 3)}
    if brdf != "standard":
        p["sheenColor"] = [round(min(1, x ** 0.5), 3) for x in c]
    if brdf in ("physical-sheen", "gltf-sheen"):
        p["sheenRoughness"] = round(rng.uniform(0.2, 0.9), 3)
    if brdf in ("physical-sheen", "gltf-sheen", "standard"):
        p["metalness"] = 0.0
    return p


def seed(out, rng, n):
    d = os.path.join(out, "seed")
    os.makedirs(os.path.join(d, "maps"))
    for i in range(n):
        brdf = SHARED_BRDFS[i % 4]
        doc = {"schema": "seed.SurfaceMaterial", "version": 1, "id": "sm-%05d" % i,
               "name": "surface_%04d" % i,
               "metadata": {"supplier": "catalogue", "capture": "2026-11", "composition": "cotton"},
               "brdf": brdf, "parameters": shared_params(rng, brdf), "maps": {}}
        if i % 10 == 0:
            colour_map(os.path.join(d, "maps", "sm%04d_color.png" % i), rng, [0.7, 0.7, 0.7])
            normal_map(os.path.join(d, "maps", "sm%04d_normal.png" % i))
            doc["maps"] = {"color": {"uri": "maps/sm%04d_color.png" % i, "colorSpace": "srgb"},
                           "normal": {"uri": "maps/sm%04d_normal.png" % i, "colorSpace": "linear"}}
        write_json(os.path.join(d, "surface_%04d.json" % i), doc)


def stacks(out, rng, n):
    d = os.path.join(out, "stacks")
    for i in range(max(1, n // 2)):
        sd = os.path.join(d, "stack_%04d" % i)
        os.makedirs(sd)
        brdf = SHARED_BRDFS[i % 4]
        sides = {}
        for side in ("front", "back"):
            p = shared_params(rng, brdf)
            colour_map(os.path.join(sd, side + "_albedo.png"), rng, p["color"])
            p["color"] = [1.0, 1.0, 1.0]  # the map carries the colour
            normal_map(os.path.join(sd, side + "_normal.png"))
            grey_map(os.path.join(sd, side + "_roughness.png"), rng.uniform(0.6, 1.0))
            sides[side] = {"parameters": p, "maps": {
                "color": {"uri": side + "_albedo.png", "colorSpace": "srgb"},
                "normal": {"uri": side + "_normal.png", "colorSpace": "linear"},
                "roughness": {"uri": side + "_roughness.png", "colorSpace": "linear"}}}
        write_json(os.path.join(sd, "texturestack.json"),
                   {"schema": "seed.TextureStack", "version": 1, "id": "ts-%05d" % i,
                    "fabricId": "fab-%05d" % i, "name": "stack_%04d" % i, "brdf": brdf,
                    "sides": sides})


def cloth_brdf(wi, wo, base, sheen, r, spec):
    """Filament cloth (desktop) BRDF without the cosine, plus an optional GGX lobe."""
    h = [a + b for a, b in zip(wi, wo)]
    ln = math.sqrt(sum(x * x for x in h))
    h = [x / ln for x in h]
    nov, nol, noh = max(wo[2], 1e-4), max(wi[2], 0.0), max(min(h[2], 1.0), 0.0)
    r = max(r, 0.045)
    a = r * r
    sin2 = max(1 - noh * noh, 2 ** -7)
    D = (2 + 1 / a) * sin2 ** (0.5 / a) / (2 * math.pi)
    V = 1 / (4 * (nol + nov - nol * nov))
    g = 0.0
    if spec > 0:
        a2 = 0.35 ** 4
        d = noh * noh * (a2 - 1) + 1
        g = spec * a2 / (math.pi * d * d) / (4 * nol * nov + 1e-3)
    return [base[c] / math.pi + sheen[c] * D * V + g for c in range(3)]


def merl(out, rng, n):
    d = os.path.join(out, "merl")
    os.makedirs(d)
    nh, nd, npd = 16, 16, 32
    scale = [1 / 1500, 1.15 / 1500, 1.66 / 1500]
    for i in range(n):
        base = fabric_colour(rng)
        sheen = [round(min(1, x ** 0.5), 3) for x in base]
        r = rng.uniform(0.4, 0.95)
        spec = 0.0 if i % 3 else 0.05
        vals = [[], [], []]
        for ih in range(nh):
            th = ((ih + 0.5) / nh) ** 2 * math.pi / 2
            for idd in range(nd):
                td = (idd + 0.5) / nd * math.pi / 2
                for ip in range(npd):
                    pd = (ip + 0.5) / npd * math.pi
                    dv = (math.sin(td) * math.cos(pd), math.sin(td) * math.sin(pd), math.cos(td))
                    wi = (math.cos(th) * dv[0] + math.sin(th) * dv[2], dv[1],
                          -math.sin(th) * dv[0] + math.cos(th) * dv[2])
                    hv = (math.sin(th), 0.0, math.cos(th))
                    k = 2 * sum(a * b for a, b in zip(wi, hv))
                    wo = tuple(k * hv[j] - wi[j] for j in range(3))
                    if wi[2] <= 1e-6 or wo[2] <= 1e-6:
                        for c in range(3):
                            vals[c].append(-1.0)
                        continue
                    f = cloth_brdf(wi, wo, base, sheen, r, spec)
                    noise = 1 + 0.01 * (rng.random() * 2 - 1)
                    for c in range(3):
                        vals[c].append(f[c] * noise / scale[c])
        with open(os.path.join(d, "measured_%03d.binary" % i), "wb") as fh:
            fh.write(struct.pack("<3i", nh, nd, npd))
            for c in range(3):
                fh.write(struct.pack("<%dd" % len(vals[c]), *vals[c]))


def fabrics(out, rng, n):
    d = os.path.join(out, "fabrics")
    os.makedirs(d)
    shutil.copytree(os.path.join(DATASETS, "weaves"), os.path.join(out, "weaves"))
    names = ["cotton_canvas", "cotton_denim", "cotton_twill", "polyester", "silk_charmeuse",
             "silk_shantung", "wool_gabardine"]
    for i in range(n):
        preset = names[i % len(names)]
        write_json(os.path.join(d, "woven_%02d.json" % i),
                   {"format": "clothfit-fabric", "version": 1, "name": "woven_%02d" % i,
                    "model": "irawan", "preset": preset, "uv_repeats": rng.choice([20, 40, 80])})


def broken(out):
    """Each broken entry: (file name, content) with the reason in its name."""
    d = os.path.join(out, "broken")
    os.makedirs(d)
    with open(os.path.join(d, "malformed_json.json"), "w") as f:
        f.write('{"schema": "clothfit.preset", "version": 1,,}\n')
    write_json(os.path.join(d, "preset_colour_out_of_range.json"),
               {"schema": "clothfit.preset", "version": 1, "model": "cloth",
                "parameters": {"base_color": [0.5, 1.5, 0.2]}})
    write_json(os.path.join(d, "surface_unknown_brdf.json"),
               {"schema": "seed.SurfaceMaterial", "version": 1, "id": "x", "name": "x",
                "brdf": "phong", "parameters": {}})
    write_json(os.path.join(d, "surface_missing_map.json"),
               {"schema": "seed.SurfaceMaterial", "version": 1, "id": "y", "name": "y",
                "brdf": "cloth", "parameters": {"color": [0.5, 0.4, 0.3]},
                "maps": {"color": {"uri": "nowhere.png"}}})
    write_json(os.path.join(d, "stack_no_sides.json"),
               {"schema": "seed.TextureStack", "version": 1, "id": "z", "fabricId": "f",
                "name": "z", "brdf": "cloth"})
    write_json(os.path.join(d, "gltf_sheen_out_of_range.gltf"),
               {"asset": {"version": "2.0"}, "extensionsUsed": ["KHR_materials_sheen"],
                "materials": [{"name": "bad", "extensions": {"KHR_materials_sheen": {
                    "sheenColorFactor": [0.5, 2.0, 0.5]}}}]})
    with open(os.path.join(d, "merl_truncated.binary"), "wb") as f:
        f.write(struct.pack("<3i", 90, 90, 180) + b"\0" * 100)
    write_json(os.path.join(d, "unknown_schema.json"), {"schema": "something.else", "version": 1})


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--count", type=int, default=200, help="materials per analytic format")
    ap.add_argument("--merl", type=int, default=None, help="MERL tables (default count/20, >= 2)")
    ap.add_argument("--fabrics", type=int, default=None, help="woven fabrics (default count/40, >= 2)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--no-broken", action="store_true")
    ap.add_argument("--quiet", action="store_true")
    a = ap.parse_args()
    rng = random.Random(a.seed)
    if os.path.exists(a.out):
        shutil.rmtree(a.out)
    os.makedirs(a.out)
    presets(a.out, rng, a.count)
    gltf(a.out, rng, a.count)
    seed(a.out, rng, a.count)
    stacks(a.out, rng, a.count)
    merl(a.out, rng, a.merl if a.merl is not None else max(2, a.count // 20))
    fabrics(a.out, rng, a.fabrics if a.fabrics is not None else max(2, a.count // 40))
    if not a.no_broken:
        broken(a.out)
    if not a.quiet:
        print("catalogue written to %s" % a.out)


if __name__ == "__main__":
    main()
