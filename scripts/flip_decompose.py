#!/usr/bin/python3
"""Where the per-pixel FLIP error of the demo previews is (docs/flip.md; issue 12).

Measurement only. Every FLIP figure comes from `clothfit compare` (fit/metrics/flip.cpp, the
report's own LDR-FLIP: display values with the scene card's tone mapping, PPD 67); this script
only makes the test images (low-passed references, supersampled previews) and the pixel masks,
and pools the per-pixel FLIP map (`compare --maps`) over them.

Needs /usr/bin/python3 with numpy (Debian python3-numpy) and oiiotool (EXR <-> FITS, since no
EXR module is installed for python). Images are 256 x 256, so everything is cheap.

Regions (per scene; the report's region is the fabric mask, reference coverage > 0.5):
  band r : fabric pixels with a non-fabric pixel within Chebyshev distance r (the silhouette)
  interior: fabric pixels not in band 2
A region's "share" is its part of the scene's FLIP sum over the fabric mask.

Usage:
  scripts/flip_decompose.py floor      --demo DIR --out DIR   (low-pass floors, noise floor)
  scripts/flip_decompose.py regions    --demo DIR --out DIR   (band / interior of the previews)
  scripts/flip_decompose.py supersample --demo DIR --out DIR --factors 1,2,4 [--models ...]
  scripts/flip_decompose.py presets    --out DIR [--ppd P] PRESET...  (previews of fitted presets)
  scripts/flip_decompose.py transplant --out DIR --sigmas 2,4 [--shift DY,DX] PRESET...
                                                            (shading vs texture)
  scripts/flip_decompose.py tables --out DIR RESULT.json...  (markdown tables of the above)
  scripts/flip_decompose.py contrast --out DIR --sigmas 4 PRESET...  (texture contrast, correlation)
  scripts/flip_decompose.py period --out DIR --sigmas 4  (texture autocorrelation on the sphere)
  scripts/flip_decompose.py fold --out DIR --ref2-dir DIR PRESET...  (the texture folded by the
                                                            weave period: periodic vs glints)
Common options: --clothfit BIN (default build/bin/clothfit), --fabrics canvas,twill.
"""
import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile

import numpy as np

SCENES = ("sphere", "drape", "swatch")


# ---------------------------------------------------------------- image I/O (via FITS)
def _fits_header(path):
    with open(path, "rb") as f:
        data = f.read()
    cards, off = {}, 0
    while True:
        block = data[off:off + 2880]
        off += 2880
        done = False
        for i in range(0, 2880, 80):
            card = block[i:i + 80].decode("ascii", "replace")
            key = card[:8].strip()
            if key == "END":
                done = True
                break
            if card[8:10] == "= ":
                cards.setdefault(key, card[10:].split("/")[0].strip())
        if done:
            return cards, data, off


def read_image(path, channels):
    """H x W x C float32 of the named channels of an image file (oiiotool --ch)."""
    tmp = tempfile.mkdtemp(prefix="flipdec")
    try:
        f = os.path.join(tmp, "x.fits")
        subprocess.run(["oiiotool", path, "--ch", ",".join(channels), "-d", "float", "-o", f],
                       check=True)
        cards, data, off = _fits_header(f)
        n = int(cards["NAXIS"])
        dims = [int(cards["NAXIS%d" % (k + 1)]) for k in range(n)]
        if n == 3:  # OIIO: NAXIS1 = channels (fastest), NAXIS2 = width, NAXIS3 = height
            c, w, h = dims
        else:
            c, (w, h) = 1, dims
        # OIIO 2.4's FITS layout (measured against a TIFF of the same EXR): one padding row,
        # then the image rows bottom-up (FITS convention).
        row = w * c
        a = np.frombuffer(data[off:off + 4 * row * (h + 1)], dtype=">f4").astype(np.float32)
        return a[row:].reshape(h, w, c)[::-1].copy()
    finally:
        shutil.rmtree(tmp)


def write_exr(path, a):
    """Write H x W x 3 float32 as a linear EXR (R, G, B), the same orientation read_image reads."""
    h, w, c = a.shape
    tmp = tempfile.mkdtemp(prefix="flipdec")
    try:
        f = os.path.join(tmp, "x.fits")
        cards = ["SIMPLE  = %20s" % "T", "BITPIX  = %20d" % -32, "NAXIS   = %20d" % 3,
                 "NAXIS1  = %20d" % c, "NAXIS2  = %20d" % w, "NAXIS3  = %20d" % h, "END"]
        head = "".join(x.ljust(80) for x in cards).encode("ascii")
        head += b" " * ((-len(head)) % 2880)
        # The layout read_image reads: one padding row, then the rows bottom-up.
        body = np.zeros(w * c, dtype=">f4").tobytes()
        body += np.ascontiguousarray(a[::-1], dtype=">f4").tobytes()
        body += b"\0" * ((-len(body)) % 2880)
        with open(f, "wb") as o:
            o.write(head + body)
        subprocess.run(["oiiotool", f, "--chnames", "R,G,B", "-d", "float", "-o", path],
                       check=True)
    finally:
        shutil.rmtree(tmp)


# ---------------------------------------------------------------- FLIP via clothfit compare
def flip_map(clothfit, ref, test, tone_mapping, exposure, workdir, ppd=None):
    """Per-pixel LDR-FLIP map (H x W) of `test` against `ref`, whole frame."""
    maps = tempfile.mkdtemp(prefix="maps", dir=workdir)
    try:
        cmd = [clothfit, "--quiet", "compare", ref, test, "--tone-mapping", tone_mapping,
               "--exposure", str(exposure), "--json", "--maps", maps]
        if ppd:
            cmd += ["--ppd", str(ppd)]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        return read_image(os.path.join(maps, "flip.exr"), ["Y"])[:, :, 0]
    finally:
        shutil.rmtree(maps)


# ---------------------------------------------------------------- masks and filters
def regions(cov):
    fabric = cov > 0.5
    out = {"fabric": fabric}
    bg = ~fabric
    h, w = fabric.shape
    for r in (1, 2, 4):
        near = np.zeros_like(bg)
        pad = np.pad(bg, r, mode="constant", constant_values=False)
        for dy in range(-r, r + 1):
            for dx in range(-r, r + 1):
                near |= pad[r + dy:r + dy + h, r + dx:r + dx + w]
        out["band%d" % r] = fabric & near
    out["interior"] = fabric & ~out["band2"]
    return out


def gauss1d(sigma):
    rad = int(np.ceil(3 * sigma))
    x = np.arange(-rad, rad + 1, dtype=np.float64)
    k = np.exp(-0.5 * (x / sigma) ** 2)
    return k / k.sum()


def conv_sep(a, k):
    """Separable convolution of H x W (x C) with zero padding."""
    r = len(k) // 2
    out = a.astype(np.float64)
    for axis in (0, 1):
        pad = [(0, 0)] * out.ndim
        pad[axis] = (r, r)
        p = np.pad(out, pad)
        acc = np.zeros_like(out)
        n = out.shape[axis]
        for i, kv in enumerate(k):
            sl = [slice(None)] * out.ndim
            sl[axis] = slice(i, i + n)
            acc += kv * p[tuple(sl)]
        out = acc
    return out


def smooth_inside(img, cov, sigma):
    """Gaussian low-pass of the fabric only (normalised convolution over the fully covered
    pixels, cov >= 0.999); the fully covered pixels are replaced, every other pixel (background,
    partly covered silhouette pixels) keeps `img`. So the result differs from `img` only in the
    fabric's interior texture."""
    full = (cov >= 0.999).astype(np.float64)
    k = gauss1d(sigma)
    num = conv_sep(img * full[:, :, None], k)
    den = conv_sep(full, k)[:, :, None]
    out = img.astype(np.float64).copy()
    sel = full > 0
    out[sel] = (num / np.maximum(den, 1e-12))[sel]
    return out.astype(np.float32)


def block_inside(img, cov, b):
    """Each b x b block's mean over its fully covered pixels, written back to those pixels
    (nearest 'upsampling' of the block means); every other pixel keeps `img`."""
    full = cov >= 0.999
    out = img.copy()
    h, w = full.shape
    for y in range(0, h, b):
        for x in range(0, w, b):
            m = full[y:y + b, x:x + b]
            if m.any():
                blk = out[y:y + b, x:x + b]
                blk[m] = img[y:y + b, x:x + b][m].mean(axis=0)
    return out


def box_down(img, f):
    h, w, c = img.shape
    return img.reshape(h // f, f, w // f, f, c).mean(axis=(1, 3)).astype(np.float32)


# ---------------------------------------------------------------- demo bookkeeping
def demo_scenes(demo, fabric, model="woven"):
    p = json.load(open(os.path.join(demo, "%s_%s.json" % (fabric, model))))
    out = []
    for s in p["fit"]["scenes"]:
        out.append(dict(name=os.path.splitext(os.path.basename(s["scene"]))[0], scene=s["scene"],
                        reference=s["reference"], reference2=s.get("reference2"),
                        tone_mapping=s["tone_mapping"], exposure=s["exposure"]))
    return out


def pool(fl, masks):
    fab = masks["fabric"]
    tot = fl[fab].sum()
    row = {"all": float(fl[fab].mean())}
    for k in ("band1", "band2", "band4", "interior"):
        m = masks[k]
        row[k] = float(fl[m].mean()) if m.any() else 0.0
        row[k + "_px"] = int(m.sum())
        row[k + "_share"] = float(fl[m].sum() / tot) if tot > 0 else 0.0
    row["fabric_px"] = int(fab.sum())
    return row


def fmt(x):
    return "%.4f" % x


# ---------------------------------------------------------------- commands
def cmd_floor(a):
    """FLIP of low-passed references (a perfect smooth preview) and the noise floor."""
    rows = []
    for fabric in a.fabrics:
        for sc in demo_scenes(a.demo, fabric):
            r1 = read_image(sc["reference"], ["R", "G", "B"])
            cov = read_image(sc["reference"], ["fabric"])[:, :, 0]
            masks = regions(cov)
            tests = {"noise floor (seed 2)": sc["reference2"]}
            r2 = read_image(sc["reference2"], ["R", "G", "B"])
            variants = []
            for s in a.sigmas:
                variants.append(("gauss %g of seed 1" % s, smooth_inside(r1, cov, s)))
                variants.append(("gauss %g of seed 2" % s, smooth_inside(r2, cov, s)))
            for b in a.blocks:
                variants.append(("block %d of seed 2" % b, block_inside(r2, cov, b)))
            for name, img in variants:
                p = os.path.join(a.out, "img", "%s_%s_%s.exr" % (fabric, sc["name"],
                                                                  name.replace(" ", "_")))
                os.makedirs(os.path.dirname(p), exist_ok=True)
                write_exr(p, img)
                tests[name] = p
            for name, p in tests.items():
                fl = flip_map(a.clothfit, sc["reference"], p, sc["tone_mapping"], sc["exposure"],
                              a.out)
                row = pool(fl, masks)
                row.update(fabric=fabric, scene=sc["name"], test=name)
                rows.append(row)
                print("%s %s %-24s fabric %s interior %s band2 %s" % (
                    fabric, sc["name"], name, fmt(row["all"]), fmt(row["interior"]),
                    fmt(row["band2"])), flush=True)
    json.dump(rows, open(os.path.join(a.out, "floor.json"), "w"), indent=1)


def model_previews(demo, fabric, model):
    return {os.path.basename(p).split("_preview")[0]: os.path.join(demo, "%s_%s" % (fabric, model), p)
            for p in os.listdir(os.path.join(demo, "%s_%s" % (fabric, model)))
            if p.endswith("_preview.exr")}


def cmd_regions(a):
    rows = []
    for fabric in a.fabrics:
        for sc in demo_scenes(a.demo, fabric):
            cov = read_image(sc["reference"], ["fabric"])[:, :, 0]
            masks = regions(cov)
            for model in a.models:
                pv = model_previews(a.demo, fabric, model)[sc["name"]]
                fl = flip_map(a.clothfit, sc["reference"], pv, sc["tone_mapping"], sc["exposure"],
                              a.out)
                row = pool(fl, masks)
                row.update(fabric=fabric, scene=sc["name"], test=model)
                rows.append(row)
                print("%s %s %-16s fabric %s interior %s band2 %s (%d px, share %.2f)" % (
                    fabric, sc["name"], model, fmt(row["all"]), fmt(row["interior"]),
                    fmt(row["band2"]), row["band2_px"], row["band2_share"]), flush=True)
    json.dump(rows, open(os.path.join(a.out, "regions.json"), "w"), indent=1)


def scaled_card(scene, f, out_dir):
    card = json.load(open(scene))
    card["gltf"] = os.path.join(os.path.dirname(os.path.abspath(scene)), card["gltf"])
    card["width"] *= f
    card["height"] *= f
    p = os.path.join(out_dir, "%s_x%d.json" % (os.path.splitext(os.path.basename(scene))[0], f))
    json.dump(card, open(p, "w"), indent=1)
    return p


def cmd_supersample(a):
    """render-preview on a copy of the scene card at f x the width and height (same camera),
    box-downsampled by f: a preview with f^2 samples per pixel (the reference integrates each
    pixel with stratified jitter; the preview takes one sample at the pixel centre)."""
    rows = []
    cards = os.path.join(a.out, "cards")
    os.makedirs(cards, exist_ok=True)
    for fabric in a.fabrics:
        for sc in demo_scenes(a.demo, fabric):
            if a.scenes and sc["name"] not in a.scenes:
                continue
            cov = read_image(sc["reference"], ["fabric"])[:, :, 0]
            masks = regions(cov)
            for model in a.models:
                preset = os.path.join(a.demo, "%s_%s.json" % (fabric, model))
                for f in a.factors:
                    card = scaled_card(sc["scene"], f, cards)
                    big = os.path.join(a.out, "img", "%s_%s_%s_x%d_full.exr" % (
                        fabric, model, sc["name"], f))
                    os.makedirs(os.path.dirname(big), exist_ok=True)
                    # the engine the preset was fitted on (fit.ibl_engine, session 8; older
                    # presets: Filament's, render-preview's default)
                    with open(preset) as fp:
                        engine = json.load(fp).get("fit", {}).get("ibl_engine", "filament")
                    subprocess.run(["nice", "-n", "10", a.clothfit, "--quiet", "render-preview",
                                    "--scene", card, "--material", preset, "--ibl-engine",
                                    engine, "--out", big], check=True)
                    img = read_image(big, ["R", "G", "B"])
                    small = os.path.join(a.out, "img", "%s_%s_%s_x%d.exr" % (
                        fabric, model, sc["name"], f))
                    write_exr(small, box_down(img, f))
                    fl = flip_map(a.clothfit, sc["reference"], small, sc["tone_mapping"],
                                  sc["exposure"], a.out)
                    row = pool(fl, masks)
                    row.update(fabric=fabric, scene=sc["name"], test="%s x%d" % (model, f))
                    rows.append(row)
                    print("%s %s %-20s fabric %s interior %s band2 %s" % (
                        fabric, sc["name"], row["test"], fmt(row["all"]),
                        fmt(row["interior"]), fmt(row["band2"])), flush=True)
    json.dump(rows, open(os.path.join(a.out, "supersample.json"), "w"), indent=1)


def cmd_presets(a):
    """FLIP of the previews a fit wrote (--images) for each preset, per region."""
    rows = []
    for preset in a.presets:
        p = json.load(open(preset))
        for s in p["fit"]["scenes"]:
            name = os.path.splitext(os.path.basename(s["scene"]))[0]
            cov = read_image(s["reference"], ["fabric"])[:, :, 0]
            fl = flip_map(a.clothfit, s["reference"], s["preview"], s["tone_mapping"],
                          s["exposure"], a.out, ppd=a.ppd)
            row = pool(fl, regions(cov))
            row.update(fabric=os.path.basename(preset), scene=name, test=preset, ppd=a.ppd or 67)
            rows.append(row)
            print("%s %s fabric %s interior %s band2 %s" % (
                os.path.basename(preset), name, fmt(row["all"]), fmt(row["interior"]),
                fmt(row["band2"])), flush=True)
    json.dump(rows, open(os.path.join(a.out, "presets%s.json" % (
        "_ppd%g" % a.ppd if a.ppd else "")), "w"), indent=1)


def preset_scenes(presets):
    """Per fitted preset and scene: (preset tag, scene name, the fit's scene record, reference
    coverage, regions(coverage), the preset's preview image)."""
    for preset in presets:
        p = json.load(open(preset))
        tag = os.path.splitext(os.path.basename(preset))[0]
        for s in p["fit"]["scenes"]:
            name = os.path.splitext(os.path.basename(s["scene"]))[0]
            cov = read_image(s["reference"], ["fabric"])[:, :, 0]
            yield tag, name, s, cov, regions(cov), read_image(s["preview"], ["R", "G", "B"])


def cmd_transplant(a):
    """Shading vs texture, per preview P (the presets given, their --images previews):
      vs smooth ref : FLIP(S_s(ref2), P): P against the second-seed reference low-passed inside
                      the fabric (Gaussian sigma s): P's error in the smooth shading alone;
      + ref texture : FLIP(ref, S_s(P) * ref2 / S_s(ref2)): P low-passed the same way, times
                      the reference's own texture (seed 2: independent noise): what P's shading
                      would score with a perfect per-pixel pattern (weave, glints) on top."""
    rows = []
    for tag, name, s, cov, masks, pv in preset_scenes(a.presets):
        r2 = read_image(s["reference2"], ["R", "G", "B"])
        for sigma in a.sigmas:
            sr2 = smooth_inside(r2, cov, sigma)
            sp = smooth_inside(pv, cov, sigma)
            ratio = np.where(sr2 > 1e-6, r2 / np.maximum(sr2, 1e-6), 1.0)
            full = (cov >= 0.999)[:, :, None]
            tex = np.where(full, sp * ratio, pv).astype(np.float32)
            base = os.path.join(a.out, "img", "%s_%s_s%g" % (tag, name, sigma))
            os.makedirs(os.path.dirname(base), exist_ok=True)
            write_exr(base + "_smoothref.exr", sr2)
            write_exr(base + "_textured.exr", tex)
            tests = [("vs smooth ref", base + "_smoothref.exr", s["preview"]),
                     ("+ ref texture", s["reference"], base + "_textured.exr")]
            if a.shift:
                # The same texture moved by (dy, dx) px (circularly): the reference's texture
                # statistics without its phase. Its correlation with the unshifted texture
                # over the interior is printed.
                moved = np.roll(ratio, a.shift, axis=(0, 1))
                sh = np.where(full, sp * moved, pv).astype(np.float32)
                write_exr(base + "_shifted.exr", sh)
                inner = masks["interior"] & full[:, :, 0]
                lum = np.array([0.2126, 0.7152, 0.0722])
                c = np.corrcoef((ratio @ lum)[inner], (moved @ lum)[inner])[0, 1]
                print("%s %s s%g: shift %s, texture correlation %.3f" % (
                    tag, name, sigma, a.shift, c), flush=True)
                tests.append(("+ shifted ref texture", s["reference"], base + "_shifted.exr"))
            for what, ref, test in tests:
                fl = flip_map(a.clothfit, ref, test, s["tone_mapping"], s["exposure"], a.out)
                row = pool(fl, masks)
                row.update(fabric=tag, scene=name, test="%s s%g" % (what, sigma))
                rows.append(row)
                print("%s %s %-20s fabric %s interior %s band2 %s" % (
                    tag, name, row["test"], fmt(row["all"]), fmt(row["interior"]),
                    fmt(row["band2"])), flush=True)
    json.dump(rows, open(os.path.join(a.out, "transplant.json"), "w"), indent=1)


def cmd_texscale(a):
    """The preview's own texture, scaled (session 14): per preview P (the presets given, their
    --images previews), FLIP(ref, S_s(P) (1 + k (P / S_s(P) - 1))) for each k in --scales, inside
    the fully covered fabric (S_s the Gaussian low-pass inside the fabric, --sigmas; every other
    pixel keeps P). k = 1 is P itself; k = 0 is S_s(P) (the "smooth" preview); k < 1 tones the
    weave pattern the maps draw down, k > 1 up."""
    rows = []
    for tag, name, s, cov, masks, pv in preset_scenes(a.presets):
        full = (cov >= 0.999)[:, :, None]
        for sigma in a.sigmas:
            sp = smooth_inside(pv, cov, sigma)
            ratio = np.where(sp > 1e-6, pv / np.maximum(sp, 1e-6), 1.0)
            for k in a.scales:
                test = np.where(full, sp * (1.0 + k * (ratio - 1.0)), pv).astype(np.float32)
                base = os.path.join(a.out, "img", "%s_%s_s%g_k%g.exr" % (tag, name, sigma, k))
                os.makedirs(os.path.dirname(base), exist_ok=True)
                write_exr(base, test)
                fl = flip_map(a.clothfit, s["reference"], base, s["tone_mapping"], s["exposure"], a.out)
                row = pool(fl, masks)
                row.update(fabric=tag, scene=name, test="texture x%g s%g" % (k, sigma))
                rows.append(row)
                print("%s %s %-20s fabric %s interior %s" % (tag, name, row["test"],
                      fmt(row["all"]), fmt(row["interior"])), flush=True)
    json.dump(rows, open(os.path.join(a.out, "texscale.json"), "w"), indent=1)


def cmd_viewbands(a):
    """View-dependent weave maps, estimated (session 14): per woven preset P (the presets given)
    and scene, the previews drawn with the maps baked from one view cosine's pairs only
    (`clothfit fit --weave-map-view-band K` writes them; --band-dirs DIR0,DIR1,DIR2 hold
    copies of P pointing at band K's maps, rendered as DIRk/<fabric>_<scene>.exr by
    `render-preview --ibl-engine threejs`), blended per pixel by NoV: linear in the view cosine
    between the bands' nodes (--band-cosines), clamped outside. Every map channel enters the
    preview linearly, so blending the images is blending the maps (same global parameters).
    NoV from a reference render's N and P AOVs (--aov-dir: aov_<scene>.exr) and the scene's
    glTF camera translation. FLIP against P's reference, pooled as `presets`."""
    dirs = a.band_dirs.split(",")
    mus = [float(x) for x in a.band_cosines.split(",")]
    order = np.argsort(mus)
    rows = []
    for preset in a.presets:
        p = json.load(open(preset))
        fabric = os.path.basename(preset).split("_")[0]
        for s in p["fit"]["scenes"]:
            name = os.path.splitext(os.path.basename(s["scene"]))[0]
            cov = read_image(s["reference"], ["fabric"])[:, :, 0]
            masks = regions(cov)
            aov = read_image(os.path.join(a.aov_dir, "aov_%s.exr" % name),
                             ["N.X", "N.Y", "N.Z", "P.X", "P.Y", "P.Z"])
            gltf = json.load(open(os.path.join(os.path.dirname(s["scene"]),
                                               json.load(open(s["scene"]))["gltf"])))
            cam = [n for n in gltf["nodes"] if "camera" in n][0]
            c = np.array(cam.get("translation", [0.0, 0.0, 0.0]))
            n = aov[:, :, 0:3]
            n = n / np.maximum(np.linalg.norm(n, axis=2, keepdims=True), 1e-12)
            v = c[None, None, :] - aov[:, :, 3:6]
            v = v / np.maximum(np.linalg.norm(v, axis=2, keepdims=True), 1e-12)
            nov = np.clip(np.abs((n * v).sum(axis=2)), 0.0, 1.0)
            imgs = [read_image(os.path.join(d, "%s_%s.exr" % (fabric, name)), ["R", "G", "B"])
                    for d in dirs]
            ms = [mus[i] for i in order]
            ims = [imgs[i] for i in order]
            # hat functions over the ascending nodes: linear interpolation, clamped at the ends
            w = np.stack([np.interp(nov, ms, np.eye(len(ms))[k]) for k in range(len(ms))], axis=2)
            blend = sum(w[:, :, k:k + 1] * ims[k] for k in range(len(ms)))
            fab = (cov > 0.0)[:, :, None]
            out = np.where(fab, blend, read_image(s["preview"], ["R", "G", "B"]))
            base = os.path.join(a.out, "img", "%s_%s_viewbands.exr" % (fabric, name))
            os.makedirs(os.path.dirname(base), exist_ok=True)
            write_exr(base, out.astype(np.float32))
            tests = [("preview", s["preview"]), ("view bands", base)]
            tests += [("band %d only (mu %.3f)" % (i, mus[i]),
                       os.path.join(dirs[i], "%s_%s.exr" % (fabric, name))) for i in range(len(dirs))]
            for what, test in tests:
                fl = flip_map(a.clothfit, s["reference"], test, s["tone_mapping"], s["exposure"], a.out)
                row = pool(fl, masks)
                row.update(fabric=fabric, scene=name, test=what,
                           nov_median=float(np.median(nov[masks["fabric"]])))
                rows.append(row)
                print("%s %s %-26s fabric %s interior %s  (median NoV %.2f)" % (
                    fabric, name, what, fmt(row["all"]), fmt(row["interior"]), row["nov_median"]),
                    flush=True)
    json.dump(rows, open(os.path.join(a.out, "viewbands.json"), "w"), indent=1)


def cmd_tables(a):
    """Markdown tables (docs/flip.md) from the JSON files the other commands wrote: each
    positional argument is one such file. Per (fabric or preset, test): the three scenes'
    FLIP over the fabric mask, their mean, and the interior / band-2 means over scenes."""
    for path in a.presets:
        rows = json.load(open(path))
        groups = {}
        for r in rows:
            groups.setdefault((r["fabric"], r["test"]), {})[r["scene"]] = r
        print("\n%s\n" % path)
        print("| fabric | test | sphere / drape / swatch | mean | interior | band 2 | band-2 share |")
        print("|---|---|---|---:|---:|---:|---:|")
        for (fab, test), sc in groups.items():
            names = [s for s in SCENES if s in sc]
            mean = lambda k: sum(sc[s][k] for s in names) / len(names)
            print("| %s | %s | %s | %s | %s | %s | %.2f |" % (
                fab, os.path.basename(str(test)), " / ".join(fmt(sc[s]["all"]) for s in names),
                fmt(mean("all")), fmt(mean("interior")), fmt(mean("band2")),
                mean("band2_share")))


def cmd_contrast(a):
    """Texture contrast: the standard deviation over the interior of L / S_s(L) - 1 (L = Rec.709
    luminance, S_s the in-fabric Gaussian low-pass), for the reference, its second seed and each
    preset's preview; and the correlation of the preview's texture with the reference's."""
    rows = []
    for preset in a.presets:
        p = json.load(open(preset))
        tag = os.path.splitext(os.path.basename(preset))[0]
        for s in p["fit"]["scenes"]:
            name = os.path.splitext(os.path.basename(s["scene"]))[0]
            cov = read_image(s["reference"], ["fabric"])[:, :, 0]
            inner = regions(cov)["interior"] & (cov >= 0.999)
            w = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
            tex = {}
            for what, path in (("ref", s["reference"]), ("ref2", s["reference2"]),
                               ("preview", s["preview"])):
                img = read_image(path, ["R", "G", "B"]) @ w
                sm = smooth_inside(img[:, :, None], cov, a.sigmas[0])[:, :, 0]
                tex[what] = (img / np.maximum(sm, 1e-6) - 1.0)[inner]
            corr = lambda x, y: float(np.corrcoef(x, y)[0, 1])
            row = dict(preset=tag, scene=name, sigma=a.sigmas[0],
                       ref=float(tex["ref"].std()), ref2=float(tex["ref2"].std()),
                       preview=float(tex["preview"].std()),
                       corr_ref_ref2=corr(tex["ref"], tex["ref2"]),
                       corr_ref_preview=corr(tex["ref"], tex["preview"]))
            rows.append(row)
            print("%-24s %-6s texture std: ref %.3f ref2 %.3f preview %.3f; corr(ref, ref2) %.2f "
                  "corr(ref, preview) %.2f" % (tag, name, row["ref"], row["ref2"], row["preview"],
                                              row["corr_ref_ref2"], row["corr_ref_preview"]),
                  flush=True)
    json.dump(rows, open(os.path.join(a.out, "contrast.json"), "w"), indent=1)


def cmd_period(a):
    """Texture scale: autocorrelation of the reference's texture L / S_s(L) - 1 over the central
    64 x 64 px of the sphere (circular, via FFT), along x and y, and its highest peak outside
    the central 5 x 5 px."""
    for fabric in a.fabrics:
        sc = [s for s in demo_scenes(a.demo, fabric) if s["name"] == "sphere"][0]
        img = read_image(sc["reference"], ["R", "G", "B"]) @ np.array(
            [0.2126, 0.7152, 0.0722], dtype=np.float32)
        cov = read_image(sc["reference"], ["fabric"])[:, :, 0]
        sm = smooth_inside(img[:, :, None], cov, a.sigmas[0])[:, :, 0]
        h, w = img.shape
        t = (img / np.maximum(sm, 1e-6) - 1.0)[h // 2 - 32:h // 2 + 32, w // 2 - 32:w // 2 + 32]
        t = t - t.mean()
        f = np.fft.fft2(t)
        ac = np.fft.fftshift(np.real(np.fft.ifft2(f * np.conj(f))))
        ac /= ac[32, 32]
        print("%s x lag 0..15: %s" % (fabric, " ".join("%.2f" % v for v in ac[32, 32:48])))
        print("%s y lag 0..15: %s" % (fabric, " ".join("%.2f" % v for v in ac[32:48, 32])))
        ac[30:35, 30:35] = -9
        i = np.unravel_index(np.argmax(ac), ac.shape)
        print("%s highest peak at (dy, dx) = (%d, %d) px: %.2f" % (fabric, i[0] - 32, i[1] - 32,
                                                                   ac[i]))


# ---------------------------------------------------------------- fold (session 14)
LUM = np.array([0.2126, 0.7152, 0.0722], dtype=np.float64)


def fabric_repeats(fabric):
    """uv_repeats of datasets/fabrics/FABRIC.json (weave tiles per uv unit)."""
    return float(json.load(open(os.path.join("datasets", "fabrics", fabric + ".json")))["uv_repeats"])


def weave_phase(path, R, cov, max_periods_per_px=1.5):
    """Per-pixel weave phase from the uv AOV (render-reference --aov uv: uv.U, uv.V = the mean
    TEXCOORD_0 over the pixel's camera samples that hit): (frac(u R), frac(v R)); one weave
    tile = 1/R in u and v (irawan.cpp Locate: X = -v R W, Y = u R H, tile W x H draft cells).
    valid = fully covered (cov >= 0.999), not in the silhouette band 2, and no pixel within 1 px
    whose uv footprint exceeds max_periods_per_px periods (uv seams, where the averaged uv is
    meaningless). Also returns the footprint (periods per px, major axis)."""
    uv = read_image(path, ["uv.U", "uv.V"]).astype(np.float64)
    U, V = uv[:, :, 0] * R, uv[:, :, 1] * R
    h, w = U.shape

    def d(a, axis):
        out = np.full_like(a, np.inf)
        if axis == 1:
            out[:, 1:-1] = (a[:, 2:] - a[:, :-2]) / 2
        else:
            out[1:-1] = (a[2:] - a[:-2]) / 2
        return out
    fp = np.maximum(np.hypot(d(U, 1), d(V, 1)), np.hypot(d(U, 0), d(V, 0)))
    bad = ~(fp <= max_periods_per_px)
    near = np.zeros_like(bad)
    pad = np.pad(bad, 1, constant_values=True)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            near |= pad[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
    interior = regions(cov)["interior"] & (cov >= 0.999)
    valid = interior & ~near
    return U - np.floor(U), V - np.floor(V), valid, interior, fp


def texture(img, cov, sigma):
    """t = L / S_sigma(L) - 1 (L = Rec.709 luminance; S the in-fabric low-pass), as `contrast`."""
    L = img.astype(np.float64) @ LUM
    sm = smooth_inside(L[:, :, None].astype(np.float32), cov, sigma)[:, :, 0].astype(np.float64)
    return L / np.maximum(sm, 1e-6) - 1.0


def same_bin_near(t, b, r, weight, look=None):
    """Per pixel, the sums over the pixels within Chebyshev distance r (itself included) that
    are in its phase bin (b, -1 = not in the mask): (sum of weight(dy, dx) t, sum of weight).
    Subtracted from a fold so that a pixel's value is predicted only from pixels of other weave
    tiles (a glint cell can span neighbouring pixels; docs/flip.md session 14). look: the bin
    each pixel is predicted for (default b)."""
    look = b if look is None else look
    h, w = b.shape
    num, den = np.zeros((h, w)), np.zeros((h, w))
    tp = np.pad(t, r)
    bp = np.pad(b, r, constant_values=-1)
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            same = (bp[r + dy:r + dy + h, r + dx:r + dx + w] == look) & (look >= 0)
            wt = weight(dy, dx)
            num += wt * np.where(same, tp[r + dy:r + dy + h, r + dx:r + dx + w], 0.0)
            den += wt * same
    return num, den


class Fold:
    """The texture averaged per phase bin (nb x nb bins of (frac(u R), frac(v R)); axis 0 = u)."""

    def __init__(self, pu, pv, mask, nb, exclude=1):
        self.nb = nb
        self.iu = np.minimum((pu * nb).astype(int), nb - 1)
        self.iv = np.minimum((pv * nb).astype(int), nb - 1)
        self.mask = mask
        self.bins = np.where(mask, self.iu * nb + self.iv, -1)
        self.flat = self.bins[mask]
        self.exclude = exclude

    def table(self, t):
        s = np.bincount(self.flat, weights=t[self.mask], minlength=self.nb * self.nb)
        n = np.bincount(self.flat, minlength=self.nb * self.nb).astype(np.float64)
        return s, n

    def mean(self, t):
        s, n = self.table(t)
        return (s / np.maximum(n, 1)).reshape(self.nb, self.nb), n.reshape(self.nb, self.nb)

    def at(self, t, loo=False, table=None):
        """The fold evaluated at each masked pixel's phase (1-D, over the mask). loo: without
        that pixel and its same-bin neighbours within self.exclude px (`t` is then also the
        texture they are left out of). table: evaluate a fold given as a (nb x nb) array."""
        if table is not None:
            return table.reshape(-1)[self.flat]
        s, n = self.table(t)
        if loo:
            es, en = same_bin_near(np.where(self.mask, t, 0.0), self.bins, self.exclude,
                                   lambda dy, dx: 1.0)
            return (s[self.flat] - es[self.mask]) / np.maximum(n[self.flat] - en[self.mask], 1)
        return s[self.flat] / np.maximum(n[self.flat], 1)

    def image(self, values):
        out = np.zeros(self.mask.shape)
        out[self.mask] = values
        return out


def local_fold(t, pu, pv, mask, nb, sigma, exclude=1, shift=(0, 0)):
    """A spatially varying fold: per pixel, the Gaussian-weighted (sigma px) mean of t over the
    masked pixels in the same phase bin (nb x nb bins), without the pixel itself and its
    same-bin neighbours within `exclude` px. The pattern's look changes with the view and light
    over a scene; this follows it. shift (du, dv) bins: the fold looked up at the pixel's
    phase bin moved by that much (a control: the same pattern out of phase)."""
    k = gauss1d(sigma)
    c = len(k) // 2
    ys, xs = np.nonzero(mask)  # work on the mask's bounding box (+ the kernel's reach)
    y0, y1 = max(ys.min() - c, 0), min(ys.max() + c + 1, mask.shape[0])
    x0, x1 = max(xs.min() - c, 0), min(xs.max() + c + 1, mask.shape[1])
    crop = (slice(y0, y1), slice(x0, x1))
    m = mask[crop]
    iu = np.minimum((pu[crop] * nb).astype(int), nb - 1)
    iv = np.minimum((pv[crop] * nb).astype(int), nb - 1)
    b = np.where(m, iu * nb + iv, -1)
    look = np.where(m, ((iu + shift[0]) % nb) * nb + (iv + shift[1]) % nb, -1)
    tm = np.where(m, t[crop], 0.0)
    num, den = np.zeros(m.shape), np.zeros(m.shape)
    for bi in range(nb * nb):
        sel = look == bi
        if not sel.any():
            continue
        src = b == bi
        num[sel] = conv_sep(np.where(src, tm, 0.0), k)[sel]
        den[sel] = conv_sep(src.astype(np.float64), k)[sel]
    es, en = same_bin_near(tm, b, exclude, lambda dy, dx: k[c + dy] * k[c + dx], look)
    return ((num - es) / np.maximum(den - en, 1e-9))[m]


def cov_(x, y):
    return float(np.mean((x - x.mean()) * (y - y.mean())))


def corr_(x, y):
    x = x - x.mean()
    y = y - y.mean()
    d = np.sqrt((x * x).sum() * (y * y).sum())
    return float((x * y).sum() / d) if d > 0 else 0.0


SYMMETRIES = [(swap, fu, fv) for swap in (False, True) for fu in (False, True) for fv in (False, True)]


def sym_name(s):
    swap, fu, fv = s
    parts = (["u<->v"] if swap else []) + (["u->-u"] if fu else []) + (["v->-v"] if fv else [])
    return " ".join(parts) if parts else "identity"


def transform(F, s):
    """A fold table (axis 0 = u phase bin, axis 1 = v) under swap / u -> -u / v -> -v (the flip of
    a bin grid is -phase up to a shift of one bin, which the shift search covers)."""
    swap, fu, fv = s
    G = F.T if swap else F
    if fu:
        G = G[::-1, :]
    if fv:
        G = G[:, ::-1]
    return G


def align(Fref, Ftest):
    """Correlation over the phase bins of Fref with every symmetry and circular shift of Ftest.
    Returns (identity correlation, best (corr, symmetry, shift), best per symmetry)."""
    nb = Fref.shape[0]
    x = Fref - Fref.mean()
    per = {}
    for s in SYMMETRIES:
        G = transform(Ftest, s)
        best = None
        for su in range(nb):
            for sv in range(nb):
                c = corr_(x, np.roll(G, (su, sv), axis=(0, 1)))
                if best is None or c > best[0]:
                    best = (c, (su, sv))
        per[sym_name(s)] = best
    ident = corr_(x, Ftest)
    b = max(per.items(), key=lambda kv: kv[1][0])
    return ident, (b[1][0], b[0], b[1][1]), per


def anti_phase(tab):
    """The circular shift (bins) that moves a fold table furthest out of phase with itself
    (the lowest autocorrelation): the control 'same pattern, wrong phase'."""
    nb = tab.shape[0]
    best = None
    for su in range(nb):
        for sv in range(nb):
            c = corr_(tab, np.roll(tab, (su, sv), axis=(0, 1)))
            if best is None or c < best[0]:
                best = (c, (su, sv))
    return best


def cmd_fold(a):
    """The reference's per-pixel texture split into the weave's periodic part and the rest.

    Per fabric and scene (the presets' fit.scenes; reference = seed 1; --ref2-dir holds the
    seed-2 renders FABRIC_SCENE_seed2.exr with the uv AOV, `render-reference --seed 2 --aov uv`,
    same spp budget and target error). Texture t = L / S4(L) - 1 over the valid interior pixels
    (weave_phase). Fold = the mean of t per phase bin (a.bins^2 bins of (frac(uR), frac(vR)));
    the local folds (a.local: bins:sigma) follow the pattern's look over the scene. Every fold
    that predicts a pixel leaves out that pixel and its same-bin neighbours within 1 px (so only
    other weave tiles, whose glints are other hash draws, predict it). Shares of var(t1):
      periodic P  = cov(t1, fold2) / var(t1): the seed-2 fold at each pixel's phase (unbiased:
                    the fold's estimation noise is independent of t1);
      est. noise  = var(fold2) / var(t1) - P: the fold's own estimation noise (the part of the
                    pattern estimate that is not the pattern);
      determ. D   = cov(t1, t2) / var(t1) (what the two seeds share);
      non-periodic deterministic G = D - P (glints; shading the 4 px low-pass leaves in t; the
                    pattern's variation that the fold's bins and window smooth away); noise 1 - D.
    Then the previews' global folds against the reference's (correlation over the bins for the 8
    symmetries x all shifts; also per row band of the fabric), and FLIP (compare, pooled over
    coverage > 0.5) of test images on the full pixels (cov >= 0.999; every other pixel keeps the
    preview; the pattern only on the valid pixels):
      smooth              S4(P)
      + fold2 [g]         S4(P) (1 + fold2(phase))  (g: global; l B/s: local, B bins, sigma s)
      + fold2 anti-phase  the same fold looked up at the phase moved by anti_phase's shift
      + ref2 texture      S4(P) ref2 / S4(ref2) (per channel, as transplant)"""
    sigma = 4.0
    rows, align_rows, flip_rows = [], [], []
    imgdir = os.path.join(a.out, "img")
    os.makedirs(imgdir, exist_ok=True)
    locals_ = [tuple(float(x) for x in item.split(":")) for item in a.local.split(",") if item]
    locals_ = [(int(b), s) for b, s in locals_]
    by_fabric = {}  # the presets by fabric (file name FABRIC_MODEL.json, the demo's naming)
    for preset in a.presets:
        tag = os.path.splitext(os.path.basename(preset))[0]
        by_fabric.setdefault(tag.split("_")[0], []).append((tag, preset))
    for fabric, presets in by_fabric.items():
        R = fabric_repeats(fabric)
        for tag, preset in presets:
            wm = json.load(open(preset)).get("weave_maps")
            if wm and float(wm["uv_repeats"]) != R:
                raise SystemExit("%s: weave_maps.uv_repeats %s != the fabric's %s" % (
                    preset, wm["uv_repeats"], R))
        p0 = json.load(open(presets[0][1]))
        for s in p0["fit"]["scenes"]:
            name = os.path.splitext(os.path.basename(s["scene"]))[0]
            r2path = os.path.join(a.ref2_dir, "%s_%s_seed2.exr" % (fabric, name))
            cov = read_image(s["reference"], ["fabric"])[:, :, 0]
            pu, pv, valid, interior, fp = weave_phase(r2path, R, cov)
            r1 = read_image(s["reference"], ["R", "G", "B"])
            r2 = read_image(r2path, ["R", "G", "B"])
            t1, t2 = texture(r1, cov, sigma), texture(r2, cov, sigma)
            F = Fold(pu, pv, valid, a.bins)
            x1, x2 = t1[valid], t2[valid]
            v1, v2 = float(x1.var()), float(x2.var())
            tab1, n1 = F.mean(t1)
            tab2, _ = F.mean(t2)
            ap_c, ap_shift = anti_phase(tab2)
            preds = {"g": (F.at(t2, loo=True), F.at(t1, loo=True))}
            anti = {"g": F.at(None, table=np.roll(tab2, (-ap_shift[0], -ap_shift[1]), axis=(0, 1)))}
            for nb, sg in locals_:
                key = "l%d/%g" % (nb, sg)
                preds[key] = (local_fold(t2, pu, pv, valid, nb, sg),
                              local_fold(t1, pu, pv, valid, nb, sg))
            nb0, sg0 = locals_[0]
            k = nb0 / a.bins
            anti["l%d/%g" % (nb0, sg0)] = local_fold(
                t2, pu, pv, valid, nb0, sg0, shift=(int(round(ap_shift[0] * k)), int(round(ap_shift[1] * k))))
            row = dict(fabric=fabric, scene=name, R=R, bins=a.bins, interior_px=int(interior.sum()),
                       valid_px=int(valid.sum()), min_bin_px=int(n1.min()),
                       periods_per_px=[float(q) for q in np.percentile(fp[valid], [5, 50, 95])],
                       std_t1=float(np.sqrt(v1)), std_t2=float(np.sqrt(v2)),
                       D=cov_(x1, x2) / v1, D_seed2=cov_(x1, x2) / v2,
                       corr_fold1_fold2=corr_(tab1, tab2),
                       anti_phase_shift=list(ap_shift), anti_phase_corr=ap_c, folds={})
            for key, (p2, p1) in preds.items():
                row["folds"][key] = dict(P=cov_(x1, p2) / v1, noise=float(p2.var()) / v1 - cov_(x1, p2) / v1,
                                         R2=1 - float((x1 - p2).var()) / v1,
                                         P_seed2=cov_(x2, p1) / v2)
            row["N"] = 1 - row["D"]
            rows.append(row)
            print("%s %-6s valid %5d/%5d px (min %d per bin), periods/px %s; std t %.3f (seed 2 "
                  "%.3f); deterministic %.3f, noise %.3f; corr(fold1, fold2) %.3f; anti-phase "
                  "shift %s (corr %.2f)" % (
                      fabric, name, row["valid_px"], row["interior_px"], row["min_bin_px"],
                      "/".join("%.2f" % q for q in row["periods_per_px"]), row["std_t1"],
                      row["std_t2"], row["D"], row["N"], row["corr_fold1_fold2"], ap_shift, ap_c))
            for key, f in row["folds"].items():
                print("   fold %-7s periodic %.3f (seed 2 %.3f; R2 %.3f; est. noise %.3f) -> "
                      "non-periodic deterministic %.3f" % (key, f["P"], f["P_seed2"], f["R2"],
                                                          f["noise"], row["D"] - f["P"]), flush=True)
            np.save(os.path.join(a.out, "%s_%s_fold_ref1.npy" % (fabric, name)), tab1)
            np.save(os.path.join(a.out, "%s_%s_fold_ref2.npy" % (fabric, name)), tab2)
            full = (cov >= 0.999)[:, :, None]
            sr2 = smooth_inside(r2, cov, sigma)
            ratio2 = np.where(sr2 > 1e-6, r2 / np.maximum(sr2, 1e-6), 1.0)
            pattern = {}
            for key, (p2, _) in preds.items():
                pattern["fold2 " + key] = F.image(p2)
                if key in anti:
                    pattern["fold2 %s anti-phase" % key] = F.image(anti[key])
            ys = np.nonzero(valid.any(axis=1))[0]
            edges = np.linspace(ys.min(), ys.max() + 1, a.bands + 1).astype(int)
            for tag, preset in presets:
                model = tag.split("_", 1)[1]
                ps = [x for x in json.load(open(preset))["fit"]["scenes"]
                      if os.path.splitext(os.path.basename(x["scene"]))[0] == name][0]
                if os.path.abspath(ps["reference"]) != os.path.abspath(s["reference"]):
                    raise SystemExit("%s: %s has another reference" % (preset, name))
                pv_img = read_image(ps["preview"], ["R", "G", "B"])
                tp = texture(pv_img, cov, sigma)
                tabp, _ = F.mean(tp)
                np.save(os.path.join(a.out, "%s_%s_fold_%s.npy" % (fabric, name, model)), tabp)
                tabr = (tab1 + tab2) / 2
                ident, best, per = align(tabr, tabp)
                xp = tp[valid]
                bands = []
                for kb in range(a.bands):
                    band = valid.copy()
                    band[:edges[kb]] = False
                    band[edges[kb + 1]:] = False
                    Fb = Fold(pu, pv, band, a.bins)
                    tb_r, _ = Fb.mean((t1 + t2) / 2)
                    tb_p, _ = Fb.mean(tp)
                    bi, bb, bper = align(tb_r, tb_p)
                    bands.append(dict(rows=[int(edges[kb]), int(edges[kb + 1])],
                                      periods_per_px=float(np.median(fp[band])), corr_identity=bi,
                                      best=[bb[0], bb[1], list(bb[2])],
                                      per_symmetry={kk: vv[0] for kk, vv in bper.items()}))
                arow = dict(fabric=fabric, scene=name, model=model,
                            std_fold_preview=float(tabp.std()), std_fold_ref=float(tabr.std()),
                            corr_identity=ident, best_corr=best[0], best_symmetry=best[1],
                            best_shift=list(best[2]),
                            per_symmetry={kk: [vv[0], list(vv[1])] for kk, vv in per.items()},
                            corr_pixel_texture=corr_(x1, xp),
                            std_preview_texture=float(xp.std()),
                            P_preview=float(F.at(tp).var()) / float(xp.var()), bands=bands)
                align_rows.append(arow)
                print("  %-15s fold std %.3f (ref %.3f); corr with the ref fold: identity %.3f, best"
                      " %.3f (%s, shift %s bins); per symmetry (best shift) %s" % (
                          model, arow["std_fold_preview"], arow["std_fold_ref"], ident, best[0],
                          best[1], best[2], ", ".join("%s %.2f" % (kk, vv[0]) for kk, vv in per.items())))
                for bd in bands:
                    print("     rows %d-%d (%.2f periods/px): identity %.2f; best %.2f %s %s" % (
                        bd["rows"][0], bd["rows"][1], bd["periods_per_px"], bd["corr_identity"],
                        bd["best"][0], bd["best"][1], bd["best"][2]))
                print("     per-pixel texture corr with the ref %.3f; the preview's own periodic "
                      "share %.3f" % (arow["corr_pixel_texture"], arow["P_preview"]), flush=True)
                sp = smooth_inside(pv_img, cov, sigma).astype(np.float64)
                tests = {"preview": ps["preview"]}
                imgs = {"smooth": sp}
                for pname, pat in pattern.items():
                    imgs["+ " + pname] = sp * np.where(valid, 1.0 + pat, 1.0)[:, :, None]
                imgs["+ ref2 texture"] = sp * ratio2
                for what, img in imgs.items():
                    out = np.where(full, img, pv_img).astype(np.float32)
                    path = os.path.join(imgdir, "%s_%s_%s.exr" % (tag, name, "".join(
                        c if c.isalnum() else "_" for c in what)))
                    write_exr(path, out)
                    tests[what] = path
                for what, path in tests.items():
                    fl = flip_map(a.clothfit, s["reference"], path, s["tone_mapping"],
                                  s["exposure"], a.out)
                    frow = pool(fl, regions(cov))
                    frow.update(fabric=fabric, scene=name, model=model, test=what)
                    flip_rows.append(frow)
                    print("     %-26s FLIP %.4f" % (what, frow["all"]), flush=True)
    json.dump(dict(variance=rows, alignment=align_rows, flip=flip_rows),
              open(os.path.join(a.out, "fold.json"), "w"), indent=1)
    print("\nFLIP, mean over scenes (coverage > 0.5):")
    groups = {}
    for r in flip_rows:
        groups.setdefault((r["fabric"], r["model"], r["test"]), []).append(r)
    for (fab, model, test), rs in groups.items():
        print("| %s | %s | %s | %s | %.4f |" % (fab, model, test, " / ".join(
            "%.4f" % r["all"] for r in rs), sum(r["all"] for r in rs) / len(rs)))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("command", choices=["floor", "regions", "supersample", "presets", "transplant", "tables", "contrast", "period", "fold", "texscale", "viewbands"])
    ap.add_argument("presets", nargs="*")
    ap.add_argument("--demo", default="/work/main/out/demo")
    ap.add_argument("--out", required=True)
    ap.add_argument("--clothfit", default="build/bin/clothfit")
    ap.add_argument("--fabrics", default="canvas,twill")
    ap.add_argument("--models", default="woven,physical-aniso,standard")
    ap.add_argument("--sigmas", default="0.5,1,2,4,8")
    ap.add_argument("--blocks", default="4,16")
    ap.add_argument("--factors", default="1,2,4")
    ap.add_argument("--shift", default="", help="transplant: also the texture moved by dy,dx px")
    ap.add_argument("--scenes", default="", help="supersample: only these scenes (sphere,drape,swatch)")
    ap.add_argument("--ref2-dir", default="",
                    help="fold: FABRIC_SCENE_seed2.exr (render-reference --seed 2 --aov uv)")
    ap.add_argument("--bins", type=int, default=16, help="fold: phase bins per axis")
    ap.add_argument("--local", default="16:16,8:16",
                    help="fold: local folds, BINS:SIGMA_PX,... (the first also gets the anti-phase control)")
    ap.add_argument("--bands", type=int, default=4, help="fold: row bands for the alignment")
    ap.add_argument("--scales", default="0,0.33,0.5,0.75,1,1.5",
                    help="texscale: factors k on the preview's own texture")
    ap.add_argument("--band-dirs", default="", help="viewbands: DIR0,DIR1,DIR2 (band previews)")
    ap.add_argument("--band-cosines", default="0.8872983346207417,0.5,0.1127016653792583",
                    help="viewbands: the bands' view cosines, in --band-dirs order")
    ap.add_argument("--aov-dir", default="", help="viewbands: aov_<scene>.exr (N and P AOVs)")
    ap.add_argument("--ppd", type=float, default=None,
                    help="presets: FLIP pixels per degree (default: compare's, 67)")
    a = ap.parse_intermixed_args()
    a.fabrics = a.fabrics.split(",")
    a.models = a.models.split(",")
    a.sigmas = [float(x) for x in a.sigmas.split(",")]
    a.blocks = [int(x) for x in a.blocks.split(",")]
    a.factors = [int(x) for x in a.factors.split(",")]
    a.scales = [float(x) for x in a.scales.split(",")]
    a.scenes = [x for x in a.scenes.split(",") if x]
    a.shift = tuple(int(x) for x in a.shift.split(",")) if a.shift else None
    a.clothfit = os.path.abspath(a.clothfit)
    os.makedirs(a.out, exist_ok=True)
    {"floor": cmd_floor, "regions": cmd_regions, "supersample": cmd_supersample,
     "presets": cmd_presets, "transplant": cmd_transplant, "tables": cmd_tables, "contrast": cmd_contrast, "period": cmd_period,
     "fold": cmd_fold, "texscale": cmd_texscale,
     "viewbands": cmd_viewbands}[a.command](a)


if __name__ == "__main__":
    sys.exit(main())
