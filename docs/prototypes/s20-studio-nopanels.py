#!/usr/bin/python3
"""Session 20 measurement (docs/fitting.md, "Where the Sadeghi fabrics' remaining error is"):
the studio map with its bright panels removed.

  oiiotool ~/.cache/clothfit/hdri/studio.exr --ch R,G,B -d float -o /tmp/studio.fits
  docs/prototypes/s20-studio-nopanels.py /tmp/studio.fits /tmp/studio-nopanels.fits
  oiiotool /tmp/studio-nopanels.fits -d half -o /tmp/studio-nopanels.exr

Texels of Rec.709 luminance > 20, grown by 2 texels, are replaced per channel by the median of
the ring 1-4 texels outside them. Prints the removed texels and their share of the map's power
(cos-latitude weighted). The FITS file is edited in place of its data (header and trailing
blocks kept as oiiotool wrote them: NAXIS1 = 3 channels, NAXIS2 = width, NAXIS3 = height).
"""
import sys

import numpy as np

src, dst = sys.argv[1:3]
raw = bytearray(open(src, "rb").read())
head = {}
pos = 0
while True:
    block = raw[pos:pos + 2880].decode("ascii", "replace")
    pos += 2880
    cards = [block[i:i + 80] for i in range(0, 2880, 80)]
    for card in cards:
        if card[:8].strip() == "END":
            break
        if card[8:10] == "= ":
            head[card[:8].strip()] = card[10:].split("/")[0].strip()
    else:
        continue
    break
n1, n2, n3 = int(head["NAXIS1"]), int(head["NAXIS2"]), int(head.get("NAXIS3", 1))
count = n1 * n2 * n3
a = np.frombuffer(bytes(raw[pos:pos + 4 * count]), dtype=">f4").reshape(n3, n2, n1).astype(np.float64)
Y = 0.2126 * a[..., 0] + 0.7152 * a[..., 1] + 0.0722 * a[..., 2]
mask = Y > 20.0
grown = mask.copy()
for dy in range(-2, 3):
    for dx in range(-2, 3):
        grown |= np.roll(np.roll(mask, dy, 0), dx, 1)
ring = np.zeros_like(grown)
for dy in range(-4, 5):
    for dx in range(-4, 5):
        ring |= np.roll(np.roll(grown, dy, 0), dx, 1)
ring &= ~grown
H, W = Y.shape
lat = (np.arange(H) + 0.5) / H * np.pi - np.pi / 2
weight = np.cos(lat)[:, None] * np.ones((1, W))
print("removed texels %d, power share %.4f" % (grown.sum(), (Y * weight)[grown].sum() / (Y * weight).sum()))
for c in range(3):
    a[..., c][grown] = np.median(a[..., c][ring])
data = a.astype(">f4").tobytes()
raw[pos:pos + len(data)] = data
open(dst, "wb").write(bytes(raw))
