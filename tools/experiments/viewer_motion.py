"""The viewer's frames in motion against the scale-1 frame of the same state: plain upscaling, temporal upsampling,
dynamic resolution.

Usage: xvfb-run -a python tools/experiments/viewer_motion.py [--scene cornell] [--size 384] [--frames 60]
           [--motion light|fly-then-still|object] [--fly-frames 30] [--object center]
           [--fixed-step 0.0333] [--scale 0.4] [--arms scale1,scale2,plain,temporal,dynamic,dynamic_temporal,plain@S]
           --out OUT.json

Each arm is one scripted `diviewer view` run with the light animated from the first frame (or the camera flying
for ``--fly-frames`` frames, then resting: ``--motion fly-then-still``; or the object ``--object`` sliding along x,
0.02 units a frame from 0.5 left of where the scene puts it, under the still camera: ``--motion object``) and
``--fixed-step``
(the frame count drives the motion, so frame i shows the same state in every arm) that saves every frame's view
(PNG, tone-mapped as shown). ``scale1`` is ``--render-scale 1`` (the reference); ``plain`` and ``temporal`` draw at
``--scale`` fixed, upscaled bilinearly or by the temporal upsampler; ``dynamic`` and ``dynamic_temporal`` are the
default dynamic resolution (its scale follows this machine's clock); ``plain@S`` is plain upscaling at the fixed
scale ``S`` (``--arms plain@0.4,plain@0.6,plain@0.8``: what a higher scale floor would buy); ``scale2`` (``--render-scale 2``, each pixel the
mean of 2x2) is the anti-aliased frame. Each frame is scored by display PSNR (8-bit PNGs) against the ``scale1``
frame of the same index, and against the ``scale2`` one where that arm runs. Measures only; needs a display (Xvfb)
and GL.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

from diviewer.imageio import read_png, write_text
from diviewer.metrics import psnr
from diviewer.outputs import dumps_rows
from diviewer.viewer.run import run_viewer
from diviewer.viewer.settings import ViewerSettings

ARMS = {"scale1": {"render_scale": 1.0}, "scale2": {"render_scale": 2.0}, "plain": {}, "temporal": {"temporal": True},
        "dynamic": {"render_scale": None}, "dynamic_temporal": {"render_scale": None, "temporal": True}}


def _finite(x) -> float | None:
    return round(float(x), 3) if np.isfinite(x) else None


def run_arm(scene: str, arm: str, size: int, frames: int, step: float, scale: float, folder: Path,
            motion: str = "light", fly_frames: int = 30, obj: str = "center") -> dict:
    fixed = arm.startswith("plain@")  # plain upscaling at the scale after the @
    changes = {"render_scale": float(arm[6:])} if fixed else {"render_scale": scale, **ARMS[arm]}
    settings = ViewerSettings(size=(size, size), vsync=False, model="auto", fixed_step=step, **changes)
    if motion == "light":
        script = [(0, lambda v: setattr(v.state, "animate_light", True))]
    elif motion == "object":  # frame i shows the object 0.02 i units right of its start
        def slide(i):
            return lambda v: v.state.move_object(obj, np.add(start[0], (0.02 * i - 0.5, 0.0, 0.0)))
        start = []
        script = [(0, lambda v: start.append(v.state.object(obj).position))]
        script += [(i, slide(i)) for i in range(frames)]
    else:  # the camera flies forward, then rests
        script = [(i, "fly", {"forward": 0.02, "dt": step}) for i in range(fly_frames)]
    script += [(i, "screenshot", {"path": folder / f"{arm}_{i:04d}.png"}) for i in range(frames)]
    scales = []
    script += [(i, lambda v: scales.append(v.render_scale)) for i in range(1, frames)]
    summary = run_viewer(scene, frames=frames, script=script, settings=settings)
    return {"settings": changes, "model": summary["model"], "gl_renderer": summary["gl_renderer"],
            "render_scales": scales, "motion": summary["motion"]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="cornell")
    ap.add_argument("--size", type=int, default=384)
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--fixed-step", type=float, default=1.0 / 30.0)
    ap.add_argument("--scale", type=float, default=0.4)
    ap.add_argument("--arms", default="scale1,scale2,plain,temporal,dynamic,dynamic_temporal")
    ap.add_argument("--warmup", type=int, default=8, help="frames left out of the 'settled' summary")
    ap.add_argument("--motion", default="light", choices=("light", "fly-then-still", "object"),
                    help="light: the light animated from the first frame; fly-then-still: the camera flies forward for "
                         "--fly-frames frames, then the view rests; object: --object slides under the still camera")
    ap.add_argument("--object", default="center", help="the object --motion object slides")
    ap.add_argument("--fly-frames", type=int, default=30)
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args(argv)
    arms = ["scale1"] + [a for a in args.arms.split(",") if a != "scale1"]
    refs = [a for a in ("scale1", "scale2") if a in arms]
    given = sys.argv[1:] if argv is None else argv
    record = {"command": "python tools/experiments/viewer_motion.py " + " ".join(given),
              "scene": args.scene, "window": [args.size, args.size], "frames": args.frames,
              "fixed_step": args.fixed_step, "scale": args.scale,
              "motion": {"light": "light animated (--light-moving)",
                         "fly-then-still": f"camera flying forward for {args.fly_frames} frames, then still",
                         "object": f"object {args.object} sliding 0.02 units a frame along x, camera still"}[args.motion],
              "metric": "display PSNR (8-bit tone-mapped PNG) against the --render-scale 1 (vs_scale1) and 2 "
                        "(vs_scale2) frames of the same index",
              "arms": {}}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for arm in arms:
            record["arms"][arm] = run_arm(args.scene, arm, args.size, args.frames, args.fixed_step, args.scale, folder,
                                          args.motion, args.fly_frames, args.object)
        for ref_arm in refs:
            ref = [read_png(folder / f"{ref_arm}_{i:04d}.png") / 255.0 for i in range(args.frames)]
            for arm in arms:
                if arm == ref_arm:
                    continue
                values = [psnr(read_png(folder / f"{arm}_{i:04d}.png") / 255.0, ref[i]) for i in range(args.frames)]
                v = np.array(values)
                settled = v[args.warmup:]
                record["arms"][arm][f"vs_{ref_arm}"] = {  # null: the same image (an infinite PSNR)
                    "psnr": [_finite(x) for x in values],
                    "min": _finite(v.min()), "median": _finite(np.median(v)), "mean": _finite(v.mean()),
                    "settled_min": _finite(settled.min()), "settled_median": _finite(np.median(settled)),
                    "frames_at_least_38db": int((v >= 38.0).sum()), "identical_frames": int(np.isinf(v).sum())}
                print(f"{arm:18s} vs {ref_arm}: min {v.min():6.2f}  median {np.median(v):6.2f}  "
                      f"settled min {settled.min():6.2f}  >= 38 dB: {(v >= 38.0).sum()}/{len(v)}")
    record["gl_renderer"] = record["arms"]["scale1"]["gl_renderer"]
    write_text(args.out, dumps_rows(record))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
