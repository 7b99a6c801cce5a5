"""Time the VXGI pass per stage across grid and screen resolutions (headless EGL).

Usage: python tools/experiments/bench_vxgi.py [--scene cornell] [--res 128 256] [--grid 32 64 128] [--trace-scale 1 2]
                                  [--bounces 1] [--frames 10] [--out bench_vxgi.json]

Three kinds of frame, each timed over --frames frames after a warm-up (median milliseconds):
  rebuild   the grid invalidated: static and dynamic geometry voxelized, light injected, mips built;
  moving    the scene's movable objects turn each frame: their voxelization, injection and mips;
  still     nothing changed: trace (+ upsample) + composite only.
The G-buffer, shadow and direct passes of the renderer are timed too (they run every frame anyway).
GL work is timed with ctx.finish() around each stage (wall clock; llvmpipe runs on the CPU). Prints a table; writes JSON with
the GL renderer string, the CPU load average when it started, and the versions.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import statistics

STAGES = ("gbuffer", "shadows", "direct", "vxgi_voxelize", "vxgi_inject", "vxgi_mip", "vxgi_bounce", "vxgi_trace",
          "vxgi_upsample", "vxgi_composite")


def bench(ctx, scene, res: int, settings, frames: int) -> dict:
    from diviewer.gl.context import stage_timer
    from diviewer.gl.renderer import Renderer
    from diviewer.gl.vxgi import VXGIPass

    timer = stage_timer(ctx, sync=True)
    r = Renderer(ctx, scene, res, res, timer=timer)
    v = VXGIPass(ctx, r, settings)
    movable = list(scene.ranges.objects)
    out = {}
    try:
        for kind in ("rebuild", "moving", "still"):
            per_stage = {s: [] for s in STAGES}
            totals = []
            for i in range(frames + 2):  # two warm-up frames
                config = scene.default
                if kind == "moving":
                    for name in movable:
                        config = config.replace_object(name, rotation=(7.0 * i, 11.0 * i, 3.0 * i))
                if kind == "rebuild":
                    v.invalidate()
                timer.reset()
                r.render(config)
                v.run(config)
                if i < 2:
                    continue
                times = dict(timer.times)
                for s in STAGES:
                    per_stage[s].append(times.get(s, 0.0))
                totals.append(sum(times.get(s, 0.0) for s in STAGES))
            out[kind] = {"total_ms": round(statistics.median(totals), 2),
                         "stages_ms": {s: round(statistics.median(t), 2) for s, t in per_stage.items()},
                         "updated": list(v.updated)}
        out["fragments"] = v.fragment_counts
    finally:
        v.release()
        r.release()
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="cornell")
    ap.add_argument("--res", type=int, nargs="+", default=[128, 256])
    ap.add_argument("--grid", type=int, nargs="+", default=[32, 64, 128])
    ap.add_argument("--trace-scale", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--bounces", type=int, default=1, choices=(1, 2))
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()

    from diviewer.gl.context import describe, headless_context
    from diviewer.gl.vxgi import VXGISettings
    from diviewer.provenance import versions
    from diviewer.scene import load_scene

    load = os.getloadavg()
    scene = load_scene(args.scene)
    rows = []
    with headless_context() as ctx:
        gl = describe(ctx)
        print(f"{gl}; load average {load[0]:.2f}; {os.cpu_count()} CPUs")
        print(f"{'res':>4} {'grid':>4} {'ts':>2} | {'rebuild':>8} {'moving':>7} {'still':>6} | "
              f"{'voxelize':>8} {'inject':>6} {'mip':>5} {'bounce':>6} {'trace':>6} {'upsmpl':>6} {'comp':>5} | "
              f"{'gbuf+shd+dir':>12}")
        for res in args.res:
            for grid in args.grid:
                for ts in args.trace_scale:
                    settings = dataclasses.replace(VXGISettings(), resolution=grid, trace_scale=ts, bounces=args.bounces)
                    b = bench(ctx, scene, res, settings, args.frames)
                    s = b["rebuild"]["stages_ms"]
                    gl_ms = s["gbuffer"] + s["shadows"] + s["direct"]
                    print(f"{res:>4} {grid:>4} {ts:>2} | {b['rebuild']['total_ms']:>8.1f} {b['moving']['total_ms']:>7.1f} "
                          f"{b['still']['total_ms']:>6.1f} | {s['vxgi_voxelize']:>8.1f} {s['vxgi_inject']:>6.1f} "
                          f"{s['vxgi_mip']:>5.1f} {s['vxgi_bounce']:>6.1f} {s['vxgi_trace']:>6.1f} {s['vxgi_upsample']:>6.1f} "
                          f"{s['vxgi_composite']:>5.1f} | {gl_ms:>12.1f}", flush=True)
                    rows.append({"res": res, "settings": dataclasses.asdict(settings), **b})
    result = {"scene": args.scene, "gl_renderer": gl, "load_average": load, "cpus": os.cpu_count(),
              "frames": args.frames, "rows": rows, "versions": versions(),
              "load_average_after": os.getloadavg()}
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
