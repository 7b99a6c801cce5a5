"""A/B the viewer's neural frame (G-buffer, pack, inference, upsample) between two variants, interleaved.

Usage: python tools/experiments/frame_probe.py --compare spin|direct [--scene cornell] [--model assets/models/cornell.onnx]
                                   [--size 768] [--gi 128] [--frames 40] [--out runs/probe.json]

  spin:    onnxruntime's worker threads spinning after each run (its default) or sleeping (diviewer's).
  direct:  the direct light as a full-resolution pass read by the neural pass, or computed inside the
           pack and the upsample (Renderer.render(direct=False), the viewer's way).

Both variants render the same still frame in the same process, alternating frame by frame, so a
change in the machine's load falls on both; each frame ends with a GPU sync (ctx.finish). The figures
are wall-clock milliseconds per frame without the display and the panel (`diviewer view --stats`
gives those). Stop other jobs first: on a 2-core machine they decide the result.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def summary(ms: list[float]) -> dict[str, float]:
    v = sorted(ms)
    return {"median": round(statistics.median(v), 2), "q25": round(v[len(v) // 4], 2),
            "q75": round(v[(3 * len(v)) // 4], 2), "min": round(v[0], 2)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--compare", choices=("spin", "direct"), required=True)
    ap.add_argument("--scene", default="cornell")
    ap.add_argument("--model", default=str(ROOT / "assets" / "models" / "cornell.onnx"))
    ap.add_argument("--size", type=int, default=768, help="frame size (square), pixels")
    ap.add_argument("--gi", type=int, default=128, help="GI resolution (square)")
    ap.add_argument("--frames", type=int, default=40, help="timed frames per variant (after 3 warm-up frames)")
    ap.add_argument("--out", default=None, help="also write the figures as JSON")
    a = ap.parse_args()

    from diviewer.gl.context import describe, headless_context
    from diviewer.gl.neural import NeuralPass
    from diviewer.gl.renderer import Renderer
    from diviewer.runtime import NeuralGI
    from diviewer.scene.loader import load_scene

    variants = ({"spinning": {"spin": True, "direct": False}, "sleeping": {"spin": False, "direct": False}}
                if a.compare == "spin" else
                {"direct pass": {"spin": False, "direct": True}, "inline": {"spin": False, "direct": False}})
    with headless_context() as ctx:
        scene = load_scene(a.scene)
        config = scene.default
        setups = {}
        for name, v in variants.items():
            r = Renderer(ctx, scene, a.size, a.size)
            npass = NeuralPass(ctx, r, NeuralGI(a.model, scene=scene, spin=v["spin"]), gi_size=(a.gi, a.gi))
            setups[name] = (r, npass, v["direct"])
        times: dict[str, list[float]] = {name: [] for name in setups}
        for i in range(3 + a.frames):
            for name, (r, npass, direct) in setups.items():
                ctx.finish()
                t0 = time.perf_counter()
                r.render(config, direct=direct)
                npass.run(**npass.inputs_for(scene, config))
                npass.composite()
                ctx.finish()
                if i >= 3:
                    times[name].append((time.perf_counter() - t0) * 1e3)
        result = {"compare": a.compare, "scene": a.scene, "model": a.model, "size": a.size, "gi": a.gi,
                  "frames": a.frames, "gl_renderer": describe(ctx), "load_average": list(os.getloadavg()),
                  "frame_ms": {name: summary(v) for name, v in times.items()}}
        for name, (r, npass, _) in setups.items():
            npass.release()
            r.release()
    for name, s in result["frame_ms"].items():
        print(f"{name:12s} median {s['median']:7.1f} ms  (q25 {s['q25']:.1f}, q75 {s['q75']:.1f}, min {s['min']:.1f})")
    if a.out:
        Path(a.out).write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
