"""A viewer run from start to end: ``run_viewer`` opens the window, applies a script, runs the frames, writes
the summary and the ``--stats`` JSON, and closes it."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from diviewer.scene.model import Scene
from diviewer.viewer.app import Viewer
from diviewer.viewer.settings import ViewerSettings


def run_viewer(scene: str | Path | Scene = "cornell", model: str | Path | None = None, frames: int | None = None,
               screenshot: str | Path | None = None, script=None, size: tuple[int, int] = (768, 768),
               vsync: bool = True, provider: str | None = None, settings: ViewerSettings | None = None,
               stats: str | Path | None = None) -> dict:
    """Open the viewer on a scene and run it until the window closes, or for ``frames`` frames.

    Args:
        scene: a shipped scene name, a .toml path or a loaded Scene.
        model: a model path, ``"auto"`` (None means the same) or ``"none"``.
        frames: render this many frames, then exit (scripted mode).
        screenshot: save the last frame's view (PNG + frame JSON) here on exit.
        size, vsync, provider: window size, vsync and execution provider, when ``settings`` is not given.
        settings: everything else (render settings, the reference's, the camera controller).
        script: actions applied before given frames: ``(frame, callable(viewer))``, ``(frame, name, kwargs)`` or
            ``{"frame": i, "action": name, **kwargs}``; names are Viewer actions (script.SCRIPT_ACTIONS) or
            ViewerState methods (set_view_mode, set_light_direction, fly, drag, toggle_recording, ...).
        stats: write the per-stage times of every frame drawn (median, p95, mean ms), the frame rate, the
            window, shading and GI resolutions, the render scales, how the stages were timed and whether the
            frames were inside the model's training ranges, as JSON, here.

    Returns:
        A summary: frames drawn, GI size, model, screenshots, view modes drawn, the reasons of those that could
        not be, mean stage times, and the GL error state before shutdown.
    """
    from diviewer.scene import load_scene
    from diviewer.viewer.report import run_summary, write_stats
    from diviewer.viewer.script import apply_action, normalise_script

    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    settings = settings or ViewerSettings(size=(int(size[0]), int(size[1])), vsync=vsync)
    changes = {"model": str(model)} if model is not None else {}
    if provider is not None:
        changes["provider"] = provider
    settings = dataclasses.replace(settings, **changes)
    if settings.provider:
        import onnxruntime as ort

        from diviewer.contract.runtime import choose_providers

        choose_providers(ort.get_available_providers(), settings.provider)  # before a window opens
    steps = normalise_script(script)
    viewer = Viewer(scene, settings)
    summary: dict = {}
    per_frame: list[dict[str, float]] = []
    shown: list[tuple[float, int]] = []  # per frame: its render scale, how many reasons it was out of range
    try:
        while frames is None or viewer.frame_index < frames:
            for action in steps.get(viewer.frame_index, ()):
                apply_action(viewer, action)
            drawn = viewer.frame_index
            if not viewer.frame():
                break
            if stats is not None and viewer.frame_index > drawn:
                per_frame.append(viewer.state.stats.last())
                shown.append((viewer.render_scale, len(viewer.state.out_of_range())))
        if screenshot is not None:
            if viewer.frame_index == 0:
                viewer.frame()
            # The state is the last frame's: save the images it showed (the temporal upsampler's, where it ran).
            last = viewer._shown[0] if viewer._shown is not None else viewer._images(viewer._sources())[0]
            viewer._save_view(Path(screenshot).with_suffix(".png"), last)
        summary = run_summary(viewer)
        if stats is not None:
            summary["stats"] = write_stats(Path(stats), viewer, per_frame, shown)
    finally:
        viewer.close()
    return summary

