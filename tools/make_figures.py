"""Rebuild the README's figures from the shipped scenes.

Usage: python tools/make_figures.py
Writes assets/figures/cornell_buffers.png: depth, normals, albedo and direct light side by side.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from diviewer import imageio
from diviewer.gl.context import create_context
from diviewer.gl.renderer import Compositor, Renderer
from diviewer.scene import load_scene

OUT = Path(__file__).resolve().parents[1] / "assets" / "figures"


def main() -> None:
    ctx = create_context()
    scene = load_scene("cornell")
    renderer = Renderer(ctx, scene, 256, 256)
    compositor = Compositor(ctx, renderer.shaders)
    f = renderer.frame()
    tiles = [imageio.depth_preview(f["depth"])[..., None].repeat(3, -1), imageio.normal_preview(f["normal"]),
             imageio.srgb8(f["albedo"]), compositor.to_ldr(f["direct"], scene.exposure)]
    gap = np.full((256, 4, 3), 255, np.uint8)
    row = np.concatenate([x for t in tiles for x in (t, gap)][:-1], axis=1)
    imageio.write_png(OUT / "cornell_buffers.png", row)
    print(f"wrote {OUT / 'cornell_buffers.png'}")


if __name__ == "__main__":
    main()
