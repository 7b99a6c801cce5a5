"""What the viewer's frame gains or loses from one of its settings: the same run in several arms, alternated.

Usage: xvfb-run -a -s "-screen 0 1920x1200x24" python tools/experiments/viewer_ab.py [--scene sponza]
           [--arms blocking,deferred,off] [--rounds 3] [--frames 100] [--size 768x768] [--light-moving]
           [--camera-moving] [--light-stops-at N] --out-dir DIR

Arms, run in turn within each round (so the machine's drift falls on all of them), each a fresh viewer process
(`diviewer.viewer.run.run_viewer`, the default settings but vsync off, the scene's shipped model):

- ``deferred``: the default: the GL stages' timer queries read once the frame is swapped
  (`diviewer.timing.StageTimer.collect`), the G-buffer flushed every `FLUSH_EVERY_DRAWS` draws;
- ``blocking``: each GL stage's timer query read at the stage's end (the viewer until 2026-11-29): reading waits for
  the stage to finish, so the driver cannot rasterize one stage while the next is submitted;
- ``off``: no GL stage timed (the panel's "per-stage timing" unticked);
- ``noflush``: the default, but the G-buffer flushed only at its end (`Renderer.flush_every` 0);
- ``offflush``: as ``off``, with a ``glFlush`` where each GL stage ends (where ``deferred`` ends its timer query):
  whether the queries' own flushes are what once made ``deferred`` faster than ``off`` (they were not: 2026-11-29);
- ``nofootprint``: the default, but a moving sun's map drawn whole (`Renderer.shadow_footprint` off), not only what
  can shade the view: with ``--light-moving``, what the footprint saves;
- ``wholerest``: the default, but a sun come to rest has its full map drawn whole at once (`Renderer.rest_in_bands`
  off), not in bands over the next frames: with ``--light-stops-at``, the frame that stalls.

``--light-moving`` animates the light from the first frame (the L key), so the shadow map is drawn every frame;
``--camera-moving`` walks the scene's camera path from the first frame (the P key); ``--light-stops-at N`` stops the
light at frame N (the summary then gives the slowest of the frames drawn with it at rest).

The timer arms of docs/speed.md's table ran before the G-buffer's flushes existed (both sides flushed at the end).
Each run writes the viewer's ``--stats`` JSON as DIR/SCENE_ARM_ROUND.json; a summary line per run and per arm is
printed (the frame rate over the run, and at the final render scale). Stop other jobs first (SIGSTOP). Measures only.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

ARMS = ("blocking", "deferred", "off", "noflush", "offflush", "nofootprint", "wholerest")

CHILD = """
import sys
from diviewer.viewer.run import run_viewer
from diviewer.viewer.settings import ViewerSettings
from diviewer.frames import parse_resolution
arm, scene, frames, size, out = sys.argv[1], sys.argv[2], int(sys.argv[3]), parse_resolution(sys.argv[4]), sys.argv[5]
settings = ViewerSettings(size=size, vsync=False, model="auto", timing=arm not in ("off", "offflush"))
if arm == "offflush":
    import contextlib
    from diviewer import timing
    from diviewer.gl.context import gl_flush
    untimed, flush = timing.StageTimer.stage, gl_flush()
    @contextlib.contextmanager
    def stage(self, name, gpu=False):
        with untimed(self, name, gpu):
            yield
        if gpu and flush is not None:
            flush()
    timing.StageTimer.stage = stage
script = {"blocking": [(0, lambda v: setattr(v.timer, "deferred", False))],
          "noflush": [(0, lambda v: setattr(v.renderer, "flush_every", 0))],
          "nofootprint": [(0, lambda v: setattr(v.renderer, "shadow_footprint", False))],
          "wholerest": [(0, lambda v: setattr(v.renderer, "rest_in_bands", False))]}.get(arm, [])
if sys.argv[6] == "1":  # the sun animated (the L key): its shadow map is drawn every frame
    script.append((0, lambda v: setattr(v.state, "animate_light", True)))
if sys.argv[7] == "1":  # the camera walks the scene's path (the P key)
    script.append((0, lambda v: v.state.toggle_path()))
if int(sys.argv[8]) > 0:  # the light stops there
    script.append((int(sys.argv[8]), lambda v: setattr(v.state, "animate_light", False)))
run_viewer(scene, frames=frames, settings=settings, stats=out, script=script)
"""


def run_arm(arm: str, scene: str, frames: int, size: str, out: Path, light_moving: bool = False,
            camera_moving: bool = False, light_stops_at: int = 0) -> dict:
    """One viewer run in its own process; its stats JSON."""
    subprocess.run([sys.executable, "-c", CHILD, arm, scene, str(frames), size, str(out), str(int(light_moving)),
                    str(int(camera_moving)), str(light_stops_at)], check=True, stdout=subprocess.DEVNULL)
    return json.loads(out.read_text())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="sponza")
    ap.add_argument("--arms", default="blocking,deferred,off", help=f"comma-separated, of {', '.join(ARMS)}")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--size", default="768x768")
    ap.add_argument("--light-moving", action="store_true", help="the light animated: shadows drawn every frame")
    ap.add_argument("--camera-moving", action="store_true", help="the camera walking the scene's path")
    ap.add_argument("--light-stops-at", type=int, default=0, help="stop the light at this frame (0: never)")
    ap.add_argument("--out-dir", type=Path, required=True)
    a = ap.parse_args(argv)
    a.out_dir.mkdir(parents=True, exist_ok=True)
    arms = [x.strip() for x in a.arms.split(",") if x.strip()]
    if not arms or set(arms) - set(ARMS):
        ap.error(f"--arms: each of {', '.join(ARMS)}, got {a.arms!r}")
    fps: dict[str, list[float]] = {arm: [] for arm in arms}
    for r in range(1, a.rounds + 1):
        for arm in arms:
            d = run_arm(arm, a.scene, a.frames, a.size, a.out_dir / f"{a.scene}_{arm}_{r}.json", a.light_moving,
                        a.camera_moving, a.light_stops_at)
            fps[arm].append(d["fps"])
            # frame_ms leaves out the first frame: [N] is frame N + 1, the first the light is still in (the action
            # at frame N runs after that frame's light step)
            stop = (f", slowest frame at rest {max(d['frame_ms'][a.light_stops_at:]):.1f} ms"
                    if a.light_stops_at > 0 else "")
            print(f"round {r} {arm}: {d['fps']:.2f} fps ({d['at_final_scale']['fps']:.2f} at the final scale "
                  f"{d['render_scales']['median']}), timing: {d['timing']}{stop}", flush=True)
    for arm, v in fps.items():
        print(f"{arm}: mean {statistics.mean(v):.2f} fps, " + ", ".join(f"{x:.2f}" for x in v))
    return 0


if __name__ == "__main__":
    sys.exit(main())
