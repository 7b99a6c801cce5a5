"""What a moving sun's smaller shadow map costs the direct light: the GL direct light of a scene's default view and
of its shipped evaluation set's cameras (square, at each ``--size``), drawn with the sun's map at each
``--shadow-sizes``, scored against the same frame drawn with the scene's own map size (the viewer's map at rest),
tone-mapped as `diviewer eval` (the scene's evaluation-set exposure).

Usage: python tools/experiments/moving_shadow.py [--scene sponza] [--size 307,768] [--shadow-sizes 1024,2048,4096]
           [--out OUT.json]

While the sun moves the viewer draws its map at ``MOVING_SHADOW_SIZE`` (with the view's footprint: the same pixels
as the whole map of that size, tests/gl/test_renderer.py), then the full size again once it rests
(docs/speed.md). Frames whose direct light does not change with the map's size (no sunlit shadow edge in view)
are counted, not scored. Measures only; needs a GL context (EGL), no Mitsuba.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from diviewer.data.dataset import read_manifest
from diviewer.evaluation.frames import default_evalset
from diviewer.gl.context import headless_context
from diviewer.gl.renderer import Renderer, RenderSettings
from diviewer.metrics import psnr, tonemap
from diviewer.scene import load_scene
from diviewer.scene.loader import config_from_dict


def measure(scene_name: str, sizes: list[int], shadow_sizes: list[int]) -> dict:
    scene = load_scene(scene_name)
    manifest = read_manifest(default_evalset(scene_name))
    exposure = float(manifest["evalset"]["tonemap"]["exposure"])
    views = [("default", scene.default)] + [(f"{f['split']}_{f['index']}", config_from_dict(scene, f["config"]))
                                            for f in manifest["frame_list"]]
    full = int(scene.shadow_size)
    out = {"scene": scene_name, "full_shadow_size": full, "exposure": exposure, "views": [v for v, _ in views],
           "sizes": {}}
    with headless_context() as ctx:
        for res in sizes:
            images = {}
            for s in sorted(set(shadow_sizes) | {full}):
                r = Renderer(ctx, scene, res, res, RenderSettings(shadow_size=s))
                try:
                    images[s] = [tonemap(r.frame(c)["direct"][..., :3], exposure) for _, c in views]
                finally:
                    r.release()
            rows = {}
            for s in shadow_sizes:
                scores = [psnr(a, b) for a, b in zip(images[s], images[full])]
                scored = [p for p in scores if math.isfinite(p)]
                rows[str(s)] = {"psnr_tm": [p if math.isfinite(p) else None for p in scores],
                                "differ": len(scored), "median": float(np.median(scored)) if scored else None,
                                "min": min(scored) if scored else None,
                                "default_view": scores[0] if math.isfinite(scores[0]) else None}
                print(f"{res}x{res}, map {s} against {full}: {len(scored)} of {len(scores)} frames differ, median "
                      f"{rows[str(s)]['median']:.1f} dB, lowest {rows[str(s)]['min']:.1f}, default view "
                      f"{scores[0]:.1f}" if scored else f"{res}x{res}, map {s}: no frame differs", flush=True)
            out["sizes"][str(res)] = rows
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="sponza")
    ap.add_argument("--size", default="307,768", help="square frame sizes (768 x 0.4, the viewer's floor: 307)")
    ap.add_argument("--shadow-sizes", default="1024,2048,4096")
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    result = measure(a.scene, [int(x) for x in a.size.split(",")], [int(x) for x in a.shadow_sizes.split(",")])
    if a.out is not None:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
