"""Rebuild the README's figures from the shipped scenes and models.

Usage: python tools/make_figures.py
Writes assets/figures/cornell_buffers.png (depth, normals, albedo, direct light) and, when
assets/models/cornell.onnx exists, assets/figures/cornell_neural.png: for test configurations (objects
the network never saw) GL direct light | neural GI | Mitsuba path tracing at 1024 spp.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from diviewer import imageio
from diviewer.gl.context import headless_context
from diviewer.gl.display import DisplayPass
from diviewer.gl.renderer import Renderer
from diviewer.paths import models_dir
from diviewer.scene import load_scene, sample_config
from diviewer.scene.colour import srgb8

OUT = Path(__file__).resolve().parents[1] / "assets" / "figures"
GAP = 4


def row(tiles: list[np.ndarray]) -> np.ndarray:
    h = tiles[0].shape[0]
    gap = np.full((h, GAP, 3), 255, np.uint8)
    return np.concatenate([x for t in tiles for x in (t, gap)][:-1], axis=1)


def main() -> None:
    scene = load_scene("cornell")
    with headless_context() as ctx:
        renderer = Renderer(ctx, scene, 256, 256)
        comp = DisplayPass(ctx, renderer.shaders)
        f = renderer.frame()
        tiles = [imageio.depth_preview(f["depth"])[..., None].repeat(3, -1), imageio.normal_preview(f["normal"]),
                 srgb8(f["albedo"]), comp.to_ldr(f["direct"], scene.exposure)]
        imageio.write_png(OUT / "cornell_buffers.png", row(tiles))
        print(f"wrote {OUT / 'cornell_buffers.png'}")
        renderer.release()
        model_path = models_dir() / "cornell.onnx"
        if model_path.is_file():
            from diviewer.gl.neural import NeuralPass
            from diviewer.reference.mitsuba import load_frame
            from diviewer.runtime import NeuralGI

            model = NeuralGI(model_path, scene=scene)
            w, h = model.resolution
            renderer = Renderer(ctx, scene, w, h)
            neural = NeuralPass(ctx, renderer, model)
            rows = []
            for seed in (3, 11):
                config = sample_config(scene, seed, "test")
                frame = renderer.frame(config)
                neural.run()
                pt = load_frame(scene, config, w, h).full(spp=1024, seed=0)
                images = [frame["direct"], neural.image(), pt]
                rows.append(row([np.kron(comp.to_ldr(im, scene.exposure), np.ones((2, 2, 1), np.uint8))
                                 for im in images]))
            gap = np.full((GAP, rows[0].shape[1], 3), 255, np.uint8)
            imageio.write_png(OUT / "cornell_neural.png", np.concatenate([rows[0], gap, rows[1]], axis=0))
            print(f"wrote {OUT / 'cornell_neural.png'}")
            neural.release()
            renderer.release()
        comp.release()


if __name__ == "__main__":
    main()
