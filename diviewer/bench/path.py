"""`diviewer bench --path FILE`: a camera path timed frame by frame, and how steady the GI stays along it.

Each row (the direct light; each model, as the viewer runs it) draws the path's frames (`--frames` evenly from its
first key to its last, default 30) at each `--res`, after `--warmup` untimed ones: per stage and per frame, with
median and p95 (`diviewer.bench.runner.GlBench`, the table's own timing). Temporal stability compares the
frame-to-frame change of each method with the path tracer's over the path's first `TEMPORAL_FRAMES` frames, the
truth rendered at `TEMPORAL_SPP` samples per pixel with one seed (so its noise holds still); without Mitsuba it is
left out with a note saying why.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

from diviewer.errors import DiviewerError

TEMPORAL_FRAMES = 6
"""Frames at the path's start whose truth is path traced for temporal stability."""
TEMPORAL_SPP = 16
"""Samples per pixel of that truth."""


def run_path_bench(settings, path_file: Path, json_out: Path | None = None, log=print) -> dict:
    """Time ``path_file``'s frames in the scene of ``settings`` (a BenchSettings); write strict JSON if asked."""
    from diviewer.bench import report
    from diviewer.bench.core import model_paths
    from diviewer.bench.runner import GlBench, gl_timing_mode, temporal_rows
    from diviewer.gl.context import headless_context
    from diviewer.contract.runtime import NeuralGI
    from diviewer.scene import load_scene
    from diviewer.scene.camera_path import frame_times, read_path

    settings.check()
    t_start = time.perf_counter()
    scene = load_scene(settings.scene)
    path, scene = read_path(path_file, scene)
    times = frame_times(path, frames=settings.frames)
    configs = [path.config_at(t, scene.default) for t in times]
    nets = {str(p): NeuralGI(p, scene=scene, provider=settings.provider) for p in model_paths(settings, scene)}
    variants = [{"path": p, "name": Path(p).stem} for p in nets]
    notes: list[str] = [] if nets else ["no model for this scene: the direct light alone is timed"]
    rows = []
    with headless_context() as ctx:
        mode = gl_timing_mode(ctx, settings.timing)
        env = report.environment(ctx, mode)
        for res in settings.resolutions:
            log(f"timing {len(configs)} frames of {path_file} at {res}x{res} ({settings.warmup} warm-up, GL: {mode})")
            gb = GlBench(ctx, scene, res, res, mode)
            try:
                rows.append(_row("direct light only", res, gb.time_direct(configs, settings.warmup), gb))
                for key, net in nets.items():
                    label = f"linear baseline ({Path(key).stem})" if net.meta.get("kind") == "linear_baseline" else \
                        f"{Path(key).stem} K={net.meta['K']} {net.meta['precision']}"
                    rows.append(_row(label, res,
                                     gb.time_model(net, configs, settings.warmup), gb, model=key))
            finally:
                gb.release()
        k = min(TEMPORAL_FRAMES, len(configs))
        temporal = None
        if k >= 2:
            seq_settings = dataclasses.replace(settings, temporal_frames=k, temporal_spp=TEMPORAL_SPP, pt_spp=(),
                                               vxgi_grids=())
            temporal = temporal_rows(ctx, seq_settings, scene, None, variants, lambda v: nets[str(v["path"])], mode,
                                     notes, log, seq=configs[:k])
        else:
            notes.append("no temporal stability: the path gives fewer than 2 frames")
    result = {"kind": "path_bench", "path": str(path_file), "scene": scene.name, "scene_hash": scene.file_hash,
              "frames": len(times), "times": times, "warmup": settings.warmup, "rows": rows,
              "temporal": temporal, "environment": env, "notes": notes,
              "seconds": round(time.perf_counter() - t_start, 3)}
    for line in table(result):
        log(line)
    if json_out is not None:
        from diviewer.outputs import write_json

        write_json(json_out, result)
    return result


def _row(label: str, res: int, timing: dict, gb, **extra) -> dict:
    return {"label": label, "resolution": [res, res], "timing": timing, "per_frame": gb.per_frame, **extra}


def table(result: dict) -> list[str]:
    """The rows as text: frame median and p95, and each stage's median (ms); then temporal stability."""
    lines = [f"{'method':<36} {'res':>5} {'median':>8} {'p95':>8}  stages (median ms)"]
    for r in result["rows"]:
        t = r["timing"]
        stages = ", ".join(f"{k} {v['median']:.2f}" for k, v in t["stages"].items())
        lines.append(f"{r['label'][:36]:<36} {r['resolution'][0]:>5} {t['frame']['median']:>8.2f} "
                     f"{t['frame']['p95']:>8.2f}  {stages}")
    temporal = result.get("temporal")
    if temporal:
        lines.append(f"temporal stability over the first {temporal['frames']} frames (reference "
                     f"{temporal['reference_spp']} spp): {temporal['measure']}")
        for name, m in temporal["methods"].items():
            lines.append(f"  {Path(name.split('|')[0]).stem:<34} " + ", ".join(f"{k} {v:.4g}" for k, v in m.items()
                                                                             if isinstance(v, float)))
    lines += [f"note: {n}" for n in result["notes"]]
    return lines


def check_path_options(args) -> None:
    """Options `bench --path` does not take, refused before any work."""
    for flag, given in (("--plot", args.plot), ("--evalset", args.evalset), ("--calib-data", args.calib_data),
                        ("--quick", args.quick), ("--render-scales", getattr(args, "render_scales", None))):
        if given:
            raise DiviewerError("does not apply to --path (a path is timed frame by frame; no accuracy table)",
                                field=flag)
