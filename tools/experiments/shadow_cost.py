"""What the sun's shadow map costs a frame, per map size: the frame re-rendering it (the sun turned a little every
frame) against the same frames with the map cached (the sun still).

Usage: python tools/experiments/shadow_cost.py [--scene sponza] [--sizes 2048,4096,8192] [--size 307]
       [--frames 8] [--rounds 2] [--out J.json]

For each map size the renderer draws ``--frames`` frames at ``--size`` x ``--size`` (307: a 768x768 window at the
viewer's render-scale floor 0.4) with the sun turned by 0.5 degrees a frame, then ``--frames`` with it still,
``--rounds`` times, and reads the direct light back after each (the wall clock covers the GPU's work). The median
difference is the shadow pass. Only the scene's first directional light moves. Stop other jobs first (SIGSTOP)
when the times matter.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def turned(config, degrees: float):
    """``config`` with its first directional light turned by ``degrees`` about the world's x axis."""
    from diviewer.scene.lights import rotate_light
    from diviewer.scene.model import DirectionalLight

    sun = next(light for light in config.lights if isinstance(light, DirectionalLight))
    return config.replace_light(sun.name, direction=rotate_light(sun, (1.0, 0.0, 0.0), degrees, None).direction)


def measure(scene, sizes: list[int], size: int, frames: int, rounds: int) -> tuple[list[dict], str]:
    """Per map size: median ms a frame with the sun moving and still, over each round, and their difference; and
    the GL renderer that drew them."""
    from diviewer.gl.context import describe, headless_context
    from diviewer.gl.renderer import Renderer, RenderSettings

    rows = []
    with headless_context() as ctx:
        gl = describe(ctx)
        for n in sizes:
            r = Renderer(ctx, scene, size, size, RenderSettings(shadow_size=n))
            try:
                for k in range(2):  # compile, allocate (at angles no timed frame uses)
                    r.render(turned(scene.default, -0.5 * (k + 1)))
                    r.read("direct")
                times = {"moving": [], "still": []}
                step = 0
                for _ in range(rounds):
                    for mode in ("moving", "still"):
                        ms = []
                        for _ in range(frames):
                            step += 1
                            t = time.perf_counter()
                            r.render(turned(scene.default, 0.5 * step if mode == "moving" else 0.0))
                            r.read("direct")
                            ms.append((time.perf_counter() - t) * 1e3)
                        times[mode].append(float(np.median(ms)))
                moving, still = float(np.median(times["moving"])), float(np.median(times["still"]))
                rows.append({"shadow_size": n, "moving_ms": moving, "still_ms": still, "shadow_pass_ms": moving - still,
                             "rounds": times, "maps_rendered": r.shadow_renders})
            finally:
                r.release()
    return rows, gl


def main(argv: list[str] | None = None) -> dict:
    from diviewer.scene import load_scene

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="sponza")
    ap.add_argument("--sizes", default="2048,4096,8192", help="shadow map sizes, texels a side")
    ap.add_argument("--size", type=int, default=307, help="square frame size")
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    scene = load_scene(a.scene)
    rows, gl = measure(scene, [int(x) for x in a.sizes.split(",")], a.size, a.frames, a.rounds)
    result = {"scene": scene.name, "frame": [a.size, a.size], "frames": a.frames, "rounds": a.rounds,
              "gl_renderer": gl, "rows": rows}
    for row in rows:
        print(f"{row['shadow_size']:6d}: sun moving {row['moving_ms']:.1f} ms, still {row['still_ms']:.1f} ms, "
              f"shadow pass {row['shadow_pass_ms']:.1f} ms", flush=True)
    if a.out:
        from diviewer.outputs import write_json

        write_json(a.out, result)
    return result


if __name__ == "__main__":
    main()
