#!/usr/bin/env python3
"""make bench's whole-process peer of `stillheart warp` (issue 20), what a user would write:
reads a Y4M video (4:4:4 or mono), applies one precomputed map to each plane of each frame with
cv2.remap (bilinear, black outside the frame) and writes the video back. The map is
`stillheart warp --map-out`'s: .npy float32 H x W x 2, NaN outside the hull.
usage: warp_remap.py MAP.npy IN.y4m OUT.y4m"""
import sys

import cv2
import numpy as np

cv2.setNumThreads(1)  # beside `stillheart warp --threads 1`, its default
xy = np.load(sys.argv[1])
xy[np.isnan(xy)] = -1.0e4  # outside the hull: a source outside the frame, black
with open(sys.argv[2], "rb") as f, open(sys.argv[3], "wb") as g:
    header = f.readline()
    tag = {t[:1]: t[1:] for t in header.split()[1:]}
    w, h, c = int(tag[b"W"]), int(tag[b"H"]), tag.get(b"C", b"420")
    if not (c.startswith(b"444") or c.startswith(b"mono")):
        sys.exit("warp_remap.py: 4:4:4 or mono only, not C%s" % c.decode())
    planes = 1 if c.startswith(b"mono") else 3
    g.write(header)
    while line := f.readline():
        frame = np.frombuffer(f.read(planes * w * h), np.uint8).reshape(planes, h, w)
        g.write(line)
        for p in frame:
            g.write(cv2.remap(p, xy, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT).data)
