"""Rebuild the figures of the README and docs/ from the shipped scenes and models.

Usage: python tools/make_figures.py [--scene NAME ...] [--spp 1024] [--model M.onnx --out-dir DIR]
Writes assets/figures/cornell_buffers.png (depth, normals, albedo, direct light) and, for each scene
(default cornell) whose model assets/models/NAME.onnx exists, assets/figures/NAME_neural.png: for two test
configurations (cornell: objects the network never saw; sponza: unseen stretches of the camera path, the most and
the least directly lit of the first 40) GL direct light | neural GI | Mitsuba path tracing at --spp, each row at
one exposure: the scene file's, or for a scene that asks for auto exposure the viewer's meter on the path-traced
frame (`diviewer.exposure.still_ev`, as `diviewer render` meters its PNGs), plus --stops. ``--model`` runs another
model of the one scene named (a candidate before it ships) and ``--out-dir`` writes the figures elsewhere.
"""

from __future__ import annotations

import argparse
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


def neural_figure(ctx, comp: DisplayPass, name: str, spp: int, seeds: tuple[int, ...] | None, stops: float,
                  model_path: Path | None = None, out_dir: Path = OUT) -> None:
    from diviewer.exposure import still_ev
    from diviewer.reference.mitsuba import load_frame
    from diviewer.render import model_pass
    from diviewer.contract.runtime import NeuralGI

    model_path = model_path or models_dir() / f"{name}.onnx"
    if not model_path.is_file():
        print(f"no {model_path}: no {name}_neural.png")
        return
    scene = load_scene(name)
    model = NeuralGI(model_path, scene=scene)
    w, h = model.resolution
    renderer = Renderer(ctx, scene, w, h)
    rows = []
    if seeds is None:  # the most and the least directly lit of the first 40 test configurations (GL only: cheap)
        lit = {s: float(renderer.frame(sample_config(scene, s, "test"))["direct"].mean()) for s in range(40)}
        seeds = (max(lit, key=lit.get), min(lit, key=lit.get))
    evs = []
    for seed in seeds:
        config = sample_config(scene, seed, "test")
        frame = renderer.frame(config)
        # as `diviewer render --model` runs it (a model of the area's direct light packs from a supersampled render)
        neural, area = model_pass(ctx, scene, renderer, model, config, renderer.settings)
        out = neural.image()
        neural.release()
        if area is not None:
            area.release()
        pt = load_frame(scene, config, w, h).full(spp=spp, seed=0)
        ev = still_ev(scene.exposure, scene.auto_exposure, pt)[0] + stops
        evs.append(ev)
        rows.append(row([np.kron(comp.to_ldr(im, ev), np.ones((2, 2, 1), np.uint8))
                         for im in (frame["direct"], out, pt)]))
    gap = np.full((GAP, rows[0].shape[1], 3), 255, np.uint8)
    imageio.write_png(out_dir / f"{name}_neural.png", np.concatenate([rows[0], gap, rows[1]], axis=0))
    print(f"wrote {out_dir / f'{name}_neural.png'} ({model_path.name}, {w}x{h}, test seeds {list(seeds)}, exposures "
          f"{', '.join(f'{ev:+.2f}' for ev in evs)} stops)")
    renderer.release()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", action="append", default=None, help="scene(s) of the neural figure (default cornell)")
    ap.add_argument("--spp", type=int, default=1024, help="path-traced samples per pixel of the right column")
    ap.add_argument("--seeds", default=None, help="test-split seeds of the two rows (default: cornell 3,11; "
                    "other scenes: the most and the least directly lit of the first 40)")
    ap.add_argument("--stops", type=float, default=0.0, help="display exposure added to the scene's (stops)")
    ap.add_argument("--model", type=Path, default=None, help="the model of the one --scene (default: its shipped one)")
    ap.add_argument("--out-dir", type=Path, default=OUT, help=f"where the figures go (default {OUT})")
    a = ap.parse_args()
    if a.model is not None and len(a.scene or ["cornell"]) != 1:
        ap.error("--model needs exactly one --scene")
    a.out_dir.mkdir(parents=True, exist_ok=True)
    scene = load_scene("cornell")
    with headless_context() as ctx:
        renderer = Renderer(ctx, scene, 256, 256)
        comp = DisplayPass(ctx, renderer.shaders)
        f = renderer.frame()
        tiles = [imageio.depth_preview(f["depth"])[..., None].repeat(3, -1), imageio.normal_preview(f["normal"]),
                 srgb8(f["albedo"]), comp.to_ldr(f["direct"], scene.exposure)]
        imageio.write_png(a.out_dir / "cornell_buffers.png", row(tiles))
        print(f"wrote {a.out_dir / 'cornell_buffers.png'}")
        renderer.release()
        for name in a.scene or ["cornell"]:
            seeds = tuple(int(x) for x in a.seeds.split(",")) if a.seeds else ((3, 11) if name == "cornell" else None)
            neural_figure(ctx, comp, name, a.spp, seeds, a.stops, a.model, a.out_dir)
        comp.release()


if __name__ == "__main__":
    main()
