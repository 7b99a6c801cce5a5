"""What a viewer run reports: the summary ``run_viewer`` returns, and the stage table JSON (``--stats``)."""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

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
        "shadow_renders": viewer.renderer.shadow_renders,
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


def write_stats(path: Path, viewer, per_frame: list[dict[str, float]]) -> dict:
    """The stage table of a scripted run as JSON: per stage median/p95/mean ms over the frames (the first,
    which compiles shaders and warms onnxruntime, left out when there are others), fps, resolutions."""
    frames = per_frame[1:] if len(per_frame) > 1 else per_frame
    table = summarize(frames)
    frame_ms = table.get("frame", {}).get("median", 0.0)
    gi, neural = viewer.gi, viewer.neural
    record = {
        "frames": len(frames),
        "fps": 1000.0 / frame_ms if frame_ms > 0 else 0.0,
        "stages_ms": table,
        "render_size": list(viewer.render_size),
        "gi_size": list(viewer.gi_size) if neural is not None else None,
        "gi_res": gi.gi_res if neural is not None else None,
        "gi": dataclasses.asdict(gi.settings),
        "model": str(viewer.model.path) if viewer.model is not None else None,
        "K": viewer.model.meta.get("K") if viewer.model is not None else None,
        "provider": viewer.state.provider or None,
        "gi_latency_ms": neural.latency_ms if neural is not None and neural.pipelined else None,
        "direct_light": (("inline" if neural.inline_direct else "pass") if neural is not None else "pass"),
        "timing": viewer.timer.method,
        "shadow_renders": viewer.renderer.shadow_renders,
        "vsync": viewer.window.vsync,
        "gl_renderer": viewer.gl_renderer,
        "load_average": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
    }
    from diviewer import imageio

    imageio.write_text(path, json.dumps(record, indent=2))  # atomic: a full disk leaves no half file
    return record
