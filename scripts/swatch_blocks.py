#!/usr/bin/python3
"""scripts/swatch_blocks.py: per-block display residuals of a preview against a reference (session 10).

    /usr/bin/python3 scripts/swatch_blocks.py REFERENCE.exr PREVIEW.exr [BLOCK]

For every BLOCK x BLOCK block (default 16, the fit's level 4) that is entirely fabric in the
reference (its `fabric` channel is 1 everywhere in the block): the block means of both images
in LINEAR radiance (as the fit averages), then three.js r187's ACESFilmicToneMapping at
exposure 1 (color / 0.6, ACESInputMat, RRTAndODTFit, ACESOutputMat, saturate) and the sRGB
encoding; prints per block row the residual preview - reference (mean over RGB) and the
reference's display value. Written for docs/fitting.md "How far the woven form can go" (the
canvas swatch's left-to-right slope). Needs numpy and oiiotool (images read as
scripts/flip_decompose.py reads them).
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from flip_decompose import read_image  # noqa: E402

ACES_IN = np.array([[0.59719, 0.35458, 0.04823], [0.07600, 0.90834, 0.01566],
                    [0.02840, 0.13383, 0.83777]])
ACES_OUT = np.array([[1.60475, -0.53108, -0.07367], [-0.10208, 1.10813, -0.00605],
                     [-0.00327, -0.07276, 1.07602]])


def display(rgb):
    """three.js ACESFilmicToneMapping (exposure 1) then the sRGB OETF, on an (..., 3) array."""
    v = (rgb / 0.6) @ ACES_IN.T
    a = v * (v + 0.0245786) - 0.000090537
    b = v * (0.983729 * v + 0.4329510) + 0.238081
    v = np.clip((a / b) @ ACES_OUT.T, 0.0, 1.0)
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * np.power(v, 1 / 2.4) - 0.055)


def main():
    if len(sys.argv) not in (3, 4):
        sys.exit(__doc__)
    ref = read_image(sys.argv[1], ["R", "G", "B"])
    pre = read_image(sys.argv[2], ["R", "G", "B"])
    cov = read_image(sys.argv[1], ["fabric"])[..., 0]
    b = int(sys.argv[3]) if len(sys.argv) == 4 else 16
    h, w, _ = ref.shape
    for j in range(h // b):
        res, val = [], []
        for i in range(w // b):
            s = (slice(j * b, (j + 1) * b), slice(i * b, (i + 1) * b))
            if cov[s].min() < 1.0:
                res.append(None)
                val.append(None)
                continue
            r = display(ref[s].reshape(-1, 3).mean(0))
            p = display(pre[s].reshape(-1, 3).mean(0))
            res.append(float((p - r).mean()))
            val.append(float(r.mean()))
        if all(x is None for x in res):
            continue
        print(j, "res", " ".join("  .   " if x is None else f"{x:+.3f}" for x in res))
        print(j, "ref", " ".join("  .   " if x is None else f"{x:.3f} " for x in val))


if __name__ == "__main__":
    main()
