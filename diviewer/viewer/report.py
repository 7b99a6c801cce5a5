"""What a viewer run reports: the summary ``run_viewer`` returns, and the stage table JSON (``--stats``)."""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import numpy as np

from diviewer.timing import summarize
from diviewer.viewer.stats import STAGES


def run_summary(viewer) -> dict:
    """Frames drawn, sizes, model, screenshots, view modes drawn and the reasons of those that could not be,
    mean stage times, and the GL error state before shutdown, of ``viewer`` (a ``viewer.app.Viewer``)."""
    st = viewer.state
    return {
        "frames": viewer.frame_index,
        "gi_size": viewer.gi_size,
        "render_size": viewer.render_size,
        "view_size": viewer.view_size,
        "render_scale": viewer.render_scale,
        "out_of_range": list(st.out_of_range()),
        "shadow_renders": viewer.renderer.shadow_renders,
        "motion": motion(viewer),
        "window_size": viewer.window.size,
        "model": st.model_name,
        "model_message": st.model_message,
        "provider": st.provider,
        "screenshots": [str(p) for p in viewer.shots.saved],
        "modes_drawn": sorted(viewer.modes_drawn),
        "unavailable": dict(viewer.unavailable),
        "stages_ms": {k: st.stats.mean(k) for k in ("frame",) + STAGES + ("panel",)},
        "config": st.config,
        "gl_error": viewer.ctx.error,
        "gl_renderer": viewer.gl_renderer,
    }


def motion(viewer) -> dict:
    """The motion state of the last frame (moving, refining, still: ``viewer.still``) and the frames in each."""
    return {"state": viewer.still.state, "frames": dict(viewer.still.counts), "refine": viewer.still.settings.refine,
            "refined_scale": viewer.scaler.refined}


def _settled(frames: list[dict[str, float]], scales: np.ndarray) -> dict:
    """The frames drawn at the run's last render scale (after dynamic resolution settled): count, median ms, fps."""
    n = len(scales) - int(np.flatnonzero(np.diff(scales))[-1] + 1) if np.any(np.diff(scales)) else len(scales)
    ms = [f["frame"] for f in frames[-n:] if "frame" in f] if len(frames) == len(scales) else []
    median = float(np.median(ms)) if ms else 0.0
    return {"frames": len(ms), "frame_ms_median": median, "fps": 1000.0 / median if median > 0 else 0.0}


def write_stats(path: Path, viewer, per_frame: list[dict[str, float]],
                shown: list[tuple[float, int]] | None = None) -> dict:
    """The stage table of a scripted run as JSON: per stage median/p95/mean ms over the frames (the first,
    which compiles shaders and warms onnxruntime, left out when there are others), fps, resolutions, the
    render scales and the training-range check (``shown``: per frame, its scale and its number of reasons), and each
    frame's time in order (``frame_ms``: where one frame stalls)."""
    frames = per_frame[1:] if len(per_frame) > 1 else per_frame
    shown = (shown[1:] if len(shown or ()) > 1 else shown) or [(viewer.render_scale, 0)]
    scales = np.array([s for s, _ in shown], np.float64)
    st, scaler = viewer.state, viewer.scaler
    table = summarize(frames)
    frame_ms = table.get("frame", {}).get("median", 0.0)
    gi, neural = viewer.gi, viewer.neural
    record = {
        "frames": len(frames),
        "fps": 1000.0 / frame_ms if frame_ms > 0 else 0.0,
        "stages_ms": table,
        "frame_ms": [round(float(f["frame"]), 2) for f in frames if "frame" in f],
        "render_size": list(viewer.render_size),
        "window_size": list(viewer.view_size),
        "render_scale": viewer.render_scale,
        "render_scales": {"min": float(scales.min()), "median": float(np.median(scales)), "max": float(scales.max()),
                          "changes": int(np.count_nonzero(np.diff(scales)))},
        "at_final_scale": _settled(frames, scales),
        "motion": motion(viewer),
        "target_fps": scaler.settings.target_fps if scaler.enabled else None,
        "scale_floor": scaler.settings.floor,
        "scale_ceiling": scaler.settings.ceiling,
        "gi_note": viewer.gi.note or None,
        "out_of_range": list(st.out_of_range()),
        "frames_out_of_range": sum(1 for _, n in shown if n),
        "exposure": st.exposure,
        "auto_exposure": st.auto_exposure,
        "clipped": st.auto.clipped,
        "gi_size": list(viewer.gi_size) if neural is not None else None,
        "gi_res": gi.gi_res if neural is not None else None,
        "gi": dataclasses.asdict(gi.settings),
        "model": str(viewer.model.path) if viewer.model is not None else None,
        "K": viewer.model.meta.get("K") if viewer.model is not None else None,
        "provider": viewer.state.provider or None,
        "edge_guard": getattr(viewer.model, "edge_guard", None),
        "gi_latency_ms": neural.latency_ms if neural is not None and neural.pipelined else None,
        "direct_light": (("inline" if neural.inline_direct else "pass") if neural is not None else "pass"),
        "timing": viewer.timer.method,
        "shadow_renders": viewer.renderer.shadow_renders,
        "drawn_last_frame": {k: {"draws": d, "triangles": t} for k, (d, t) in viewer.renderer.drawn.items()},
        "culling": viewer.renderer.culling,
        "back_faces": viewer.renderer.back_faces,
        "vsync": viewer.window.vsync,
        "gl_renderer": viewer.gl_renderer,
        "load_average": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
    }
    from diviewer import imageio

    imageio.write_text(path, json.dumps(record, indent=2))  # atomic: a full disk leaves no half file
    return record
