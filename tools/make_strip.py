"""A strip of a rendered camera path: the frames of a `diviewer render --path` folder side by side, in order.

Usage: python tools/make_strip.py WALK_DIR --out assets/figures/sponza_walk_strip.png [--frames 5]

WALK_DIR is the --out folder of `diviewer render --path FILE --out WALK_DIR`; its frames/NNNNNN.png are taken
evenly (all of them by default) and written as one PNG, atomically. An existing --out is refused.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np


def strip(frames: list[Path], count: int | None = None) -> np.ndarray:
    """The frames (count of them, evenly from the first to the last) side by side."""
    if not frames:
        raise SystemExit("no frames/NNNNNN.png in the folder: render the path first (diviewer render --path)")
    if count is not None and 1 <= count < len(frames):
        frames = [frames[round(i * (len(frames) - 1) / max(count - 1, 1))] for i in range(count)]
    images = [np.asarray(iio.imread(f))[..., :3] for f in frames]
    if len({im.shape for im in images}) != 1:
        raise SystemExit("the frames differ in size: render them with one --res")
    return np.concatenate(images, axis=1)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("walk", type=Path, help="the --out folder of diviewer render --path")
    ap.add_argument("--out", type=Path, required=True, help="the strip's PNG (not overwritten)")
    ap.add_argument("--frames", type=int, default=None, help="how many frames, evenly (default: all)")
    args = ap.parse_args(argv)
    if args.out.exists():
        raise SystemExit(f"{args.out} exists: give another name or delete it")
    image = strip(sorted((args.walk / "frames").glob("[0-9]" * 6 + ".png")), args.frames)
    tmp = args.out.with_name(args.out.name + ".tmp.png")
    iio.imwrite(tmp, image, optimize=True)
    tmp.replace(args.out)
    print(f"{args.out}: {image.shape[1]}x{image.shape[0]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
