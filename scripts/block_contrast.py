#!/usr/bin/python3
"""scripts/block_contrast.py: how much a reference varies at the fit's block scale, in display space.

    /usr/bin/python3 scripts/block_contrast.py [--clothfit BIN] [--block 16] CARD:REFERENCE ...

Written for issue 12's "Generalises" (docs/fitting.md, "Another environment, on three.js-engine
fits (session 9)"): a block display RMSE is an absolute figure, so an environment whose
references span more of the display range raises every model's error. For each reference:
  - tone-maps it with the card's tone mapping and exposure (`clothfit tonemap --scene CARD`,
    8-bit sRGB PNG: the display values, quantised to 1/255);
  - cuts the image into BLOCK x BLOCK pixel blocks (16 = the fits' level 4 on the 256 x 256
    cards) and keeps the blocks whose mean `fabric` coverage (the reference's channel) is >= 0.5;
  - prints the kept blocks, their mean display value (RGB mean) and the standard deviation of
    the block means over blocks and channels: the RMSE of the best constant grey per channel,
    i.e. the error of a preview that shows no shading at all.
It approximates the fit's blocks (the fit also drops blocks the preview does not cover and
works on the preview's float display values); it is a scale, not the fit's figure.
Needs /usr/bin/python3 with numpy and oiiotool (images read as scripts/flip_decompose.py does).
"""
import argparse
import os
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from flip_decompose import read_image  # noqa: E402


def blocks(a, b):
    h, w = a.shape[:2]
    return a[:h - h % b, :w - w % b].reshape(h // b, b, w // b, b, -1).mean(axis=(1, 3))


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--clothfit", default="build/bin/clothfit")
    p.add_argument("--block", type=int, default=16)
    p.add_argument("pairs", nargs="+", help="CARD:REFERENCE")
    a = p.parse_args()
    print("reference\tblocks\tmean\tstd")
    with tempfile.TemporaryDirectory(prefix="blockcontrast") as tmp:
        for pair in a.pairs:
            card, ref = pair.split(":", 1)
            png = os.path.join(tmp, "d.png")
            subprocess.run([a.clothfit, "--quiet", "tonemap", "--scene", card, ref, png], check=True)
            disp = read_image(png, ["R", "G", "B"]).astype(np.float64)
            if disp.max() > 1.5:  # 8-bit read as 0..255
                disp /= 255.0
            cov = read_image(ref, ["fabric"])[:, :, 0].astype(np.float64)
            bd, bc = blocks(disp, a.block), blocks(cov[:, :, None], a.block)[..., 0]
            keep = bc >= 0.5
            v = bd[keep]
            print("%s\t%d\t%.4f\t%.4f" % (ref, keep.sum(), v.mean(), v.std()))


if __name__ == "__main__":
    main()
