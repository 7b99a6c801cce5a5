"""What culling the back faces of single-sided materials changes in a scene's G-buffer, and what it saves.

Usage: python tools/experiments/back_faces.py [--scene sponza] [--path-steps 40] [--res 228x128]
       [--time] [--time-size 307] [--frames 12] [--rounds 3] [--out J.json]

The renderer leaves the back faces of materials whose file calls them single-sided (glTF's ``doubleSided``,
false unless said; a TOML material's ``double_sided``) out of the G-buffer (``Renderer.back_faces``). Where a
closed surface is seen from outside its back faces are behind its front faces, so nothing changes; where the
camera looks through a seam, a hole or at an open sheet from behind, the pixel shows what lies beyond, while the
path tracer (both faces) shows the sheet. For the scene file's default view and ``--path-steps`` cameras along
its camera walk, at the capture's ``--res``, this counts the pixels whose depth, normal or albedo change, in all
and per material (that material alone single-sided). ``--time`` draws the default view's G-buffer pass at
``--time-size`` squared ``--frames`` times each way, ``--rounds`` times alternating, and reports the medians.
Stop other jobs first (SIGSTOP) when the times matter.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

BUFFERS = ("depth", "normal", "albedo")


def cameras(scene, steps: int) -> list:
    """The default view, then ``steps`` cameras evenly along the walk (none without one)."""
    from diviewer.scene.sampler import camera_on_path

    out = [("default", scene.default)]
    if scene.ranges.camera is not None:
        for s in np.linspace(0.0, 1.0, steps, endpoint=False):
            out.append((f"path {s:.3f}", dataclasses.replace(scene.default, camera=camera_on_path(scene, float(s)))))
    return out


def gbuffer(r, config) -> dict[str, np.ndarray]:
    from diviewer.gl.renderer import FrameView

    r.render(config, direct=False)
    r._gbuffer_pass(FrameView(config, config.camera.view_matrix(), config.camera.projection(r.width / r.height),
                              r._bounds[2]))
    return {k: r.read(k) for k in BUFFERS}


def changed(a: dict, b: dict) -> np.ndarray:
    """(H, W) bool: any of depth, normal, albedo differs."""
    out = np.zeros(a["depth"].shape, bool)
    for k in BUFFERS:
        d = np.abs(a[k] - b[k])
        out |= (d if d.ndim == 2 else d.max(axis=-1)) > 1e-6
    return out


def with_sides(scene, single: set[str]):
    """``scene`` with the materials in ``single`` single-sided and every other one double-sided."""
    mats = {k: dataclasses.replace(m, double_sided=k not in single) for k, m in scene.materials.items()}
    return dataclasses.replace(scene, materials=mats)


def differences(ctx, scene, configs: list, width: int, height: int) -> dict:
    """Per camera, the share of pixels that culling changes (the file's sides), and per material the pixels it
    changes when it alone is single-sided."""
    from diviewer.gl.renderer import Renderer

    single = {k for k, m in scene.materials.items() if not m.double_sided}
    r = Renderer(ctx, scene, width, height, back_faces=True)
    try:
        both = [gbuffer(r, c) for _, c in configs]
        r.back_faces = False
        rows = [{"camera": name, "changed_share": float(changed(f, gbuffer(r, c)).mean())}
                for (name, c), f in zip(configs, both)]
        per_material = {}
        for m in sorted(single):
            r.scene = with_sides(scene, {m})
            per_material[m] = int(sum(changed(f, gbuffer(r, c)).sum() for (_, c), f in zip(configs, both)))
    finally:
        r.release()
    shares = [row["changed_share"] for row in rows]
    return {"single_sided": sorted(single), "cameras": rows, "changed_share_mean": float(np.mean(shares)),
            "changed_share_max": float(np.max(shares)), "changed_pixels_per_material": per_material,
            "pixels": len(configs) * width * height}


def timing(ctx, scene, size: int, frames: int, rounds: int) -> dict:
    """Median G-buffer pass time (ms, to glFinish) of the default view with back faces culled and kept."""
    from diviewer.gl.renderer import FrameView, Renderer

    config = scene.default
    r = Renderer(ctx, scene, size, size)
    try:
        r.render(config, direct=False)
        frame = FrameView(config, config.camera.view_matrix(), config.camera.projection(1.0), r._bounds[2])
        out: dict[str, list] = {"culled_ms": [], "kept_ms": []}
        for _ in range(rounds):
            for kept in (False, True):
                r.back_faces = kept
                walls = []
                for _ in range(frames):
                    t = time.perf_counter()
                    r._gbuffer_pass(frame)
                    ctx.finish()
                    walls.append(time.perf_counter() - t)
                out["kept_ms" if kept else "culled_ms"].append(round(1000 * float(np.median(walls)), 1))
        out["triangles"] = r.drawn["gbuffer"][1]
    finally:
        r.release()
    return {"size": size, "frames": frames, **out}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="sponza")
    ap.add_argument("--path-steps", type=int, default=40, help="cameras along the walk, besides the default")
    ap.add_argument("--res", default="228x128", help="WxH of the pixel counts (the capture's)")
    ap.add_argument("--time", action="store_true", help="also time the default view's G-buffer both ways")
    ap.add_argument("--time-size", type=int, default=307, help="square size of the timed pass (768 at scale 0.4)")
    ap.add_argument("--frames", type=int, default=12)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()

    from diviewer.gl.context import create_context
    from diviewer.scene import load_scene

    scene = load_scene(args.scene)
    w, h = (int(x) for x in args.res.lower().split("x"))
    ctx = create_context("egl")
    result = {"scene": args.scene, "res": [w, h], **differences(ctx, scene, cameras(scene, args.path_steps), w, h)}
    mean, worst = 100 * result["changed_share_mean"], 100 * result["changed_share_max"]
    print(f"{len(result['cameras'])} cameras at {w}x{h}: pixels changed by culling {mean:.4f} % (mean), "
          f"{worst:.4f} % (worst camera)")
    for m, n in sorted(result["changed_pixels_per_material"].items(), key=lambda kv: -kv[1]):
        print(f"  {m:14s} {n:7d} px  {100 * n / result['pixels']:.4f} %")
    if args.time:
        result["time"] = timing(ctx, scene, args.time_size, args.frames, args.rounds)
        print(f"default view, G-buffer at {args.time_size}^2: culled {result['time']['culled_ms']} ms, "
              f"kept {result['time']['kept_ms']} ms")
    if args.out:
        args.out.write_text(json.dumps(result, indent=1) + "\n")
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
