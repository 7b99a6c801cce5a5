"""VXGI's error against the path tracer on a scene's frames, per setting (and direct light's, for scale).

Usage: python tools/experiments/vxgi_accuracy.py [--scene cornell] [--res 64] [--frames 4] [--spp 1024]
                                     [--set resolution=32,64,128 bounces=1,2 ...] [--out acc.json]
Frames: the scene's default configuration, then test-split configurations drawn with seeds 1, 2, ...
The reference is rendered once per run (Mitsuba, `train` extra). --set takes VXGISettings fields with
comma-separated values; every combination is scored (MSE, PSNR). Prints a table; writes JSON.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json

import numpy as np


def parse_value(field, text: str):
    """A --set value as the settings field's type (the annotations are strings here)."""
    kind = field.type if isinstance(field.type, str) else field.type.__name__
    if kind == "bool":
        return text.lower() in ("1", "true", "yes")
    return int(text) if kind == "int" else float(text)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="cornell")
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--frames", type=int, default=4)
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--set", nargs="*", default=["resolution=32,64,128"])
    ap.add_argument("--out", default=None)
    args = ap.parse_args()

    from diviewer.gl.context import headless_context
    from diviewer.gl.renderer import Renderer
    from diviewer.gl.vxgi import VXGIPass, VXGISettings
    from diviewer.metrics import psnr
    from diviewer.reference import mitsuba as ref
    from diviewer.scene import load_scene, sample_config

    scene = load_scene(args.scene)
    configs = [scene.default] + [sample_config(scene, s, "test") for s in range(1, args.frames)]
    ref.select_variant()
    refs = [ref.load_frame(scene, c, args.res, args.res).full(spp=args.spp, seed=0) for c in configs]
    fields = {f.name: f for f in dataclasses.fields(VXGISettings)}
    grid = {}
    for item in args.set:
        name, values = item.split("=")
        grid[name] = [parse_value(fields[name], v) for v in values.split(",")]
    rows = []
    with headless_context() as ctx:
        r = Renderer(ctx, scene, args.res, args.res)
        direct = [r.frame(c)["direct"] for c in configs]
        d_mse = [float(np.mean((d - p) ** 2)) for d, p in zip(direct, refs)]
        print(f"direct light only: MSE {np.mean(d_mse):.5f}  PSNR {np.mean([psnr(d, p) for d, p in zip(direct, refs)]):.2f}")
        for combo in itertools.product(*grid.values()):
            settings = VXGISettings(**dict(zip(grid, combo)))
            mse, ps = [], []
            for c, p in zip(configs, refs):
                r.render(c)
                v = VXGIPass(ctx, r, settings)
                v.run(c)
                img = v.read("vxgi")
                v.release()
                mse.append(float(np.mean((img - p) ** 2)))
                ps.append(float(psnr(img, p)))
            rows.append({"settings": dataclasses.asdict(settings), "mse": mse, "psnr": ps})
            print(f"{dict(zip(grid, combo))}: MSE {np.mean(mse):.5f}  PSNR {np.mean(ps):.2f}  per frame "
                  + " ".join(f"{m:.5f}" for m in mse), flush=True)
        r.release()
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"scene": args.scene, "res": args.res, "spp": args.spp, "direct_mse": d_mse, "rows": rows}, f,
                      indent=1)


if __name__ == "__main__":
    main()
