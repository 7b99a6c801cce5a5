"""What the panel shows of the viewer beyond its state: a frozen ``PanelView`` the app builds each frame from its
parts (window, GI control, scale controller, motion tracker, reference, timer), after the frame's images are drawn.

The panel reads the viewer only through it, and asks for the viewer's actions by returning requests (an action
name of ``script.SCRIPT_ACTIONS`` and its keyword arguments) that the app applies once the panel has drawn.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

Request = tuple[str, dict]
"""A viewer action the panel asks for: its name (one of ``script.SCRIPT_ACTIONS``) and its keyword arguments."""


@dataclass(frozen=True)
class PanelView:
    """The viewer as the panel shows it in one frame."""

    window_size: tuple[int, int]
    """The window's size in screen units."""
    fb_size: tuple[int, int]
    """The window's framebuffer size in pixels."""
    vsync: bool
    render_size: tuple[int, int]
    """The shading resolution."""
    render_scale: float
    """The render scale of the frame drawn."""
    gi_size: tuple[int, int]
    """The GI resolution (the render size without a model)."""
    target_fps: float
    """The frame rate dynamic resolution holds (0: off)."""
    motion: str
    """The frame's motion state (``still.MOTION_STATES``)."""
    frame_counts: tuple[tuple[str, int], ...]
    """How many frames were drawn in each motion state."""
    model_path: Path | None
    """The loaded model's file, or None."""
    candidates: tuple[Path, ...]
    """The scene's shipped models."""
    gi_sizes: tuple[tuple[str, tuple[int, int]], ...]
    """(GI resolution asked for, the size it runs at) for each that the loaded model can run at
    (``GIControl.offered``)."""
    gi_note: str
    """Why the GI runs at another shape than the window's, or is extrapolated (``GIControl.note``)."""
    neural: bool
    """Whether a neural pass runs (a model is loaded)."""
    pipelined: bool
    """Inference runs one frame behind, on a worker thread."""
    latency_ms: float
    """How old the shown GI is, when pipelined."""
    inline_direct: bool
    """This frame's direct light was computed inside the neural pass's pack and upsample."""
    unavailable: tuple[tuple[str, str], ...]
    """(view mode, why) of the modes that could not be drawn."""
    reference_available: bool
    """Whether the path-traced reference can be rendered at all."""
    reference_status: str
    """The reference's status line, while a shown mode is the reference (else empty)."""
    reference_ready: bool
    """Whether a reference image of the current request is ready, while one is shown."""
    gl_renderer: str
    timing_method: str
    """How GL stages are timed, in words."""
    timer_sync: bool
    """Whether GL stages are timed."""


def panel_view(window, gi, scaler, still, reference, timer, *, render_size: tuple[int, int], render_scale: float,
               unavailable: dict[str, str], candidates, gl_renderer: str, reference_shown: bool) -> PanelView:
    """The frame's ``PanelView`` from the viewer's parts: ``window`` (``viewer.window.Window``), ``gi``
    (``viewer.gi.GIControl``), ``scaler`` (``viewer.scale.ScaleController``), ``still``
    (``viewer.still.StillTracker``), ``reference`` (``reference.progressive.ProgressiveReference``) and ``timer``
    (the frame's ``timing`` timer); ``reference_shown``: a shown view mode is the reference."""
    neural = gi.neural
    latest = reference.latest() if reference_shown else None
    return PanelView(
        window_size=tuple(window.size), fb_size=tuple(window.fb_size), vsync=bool(window.vsync),
        render_size=tuple(render_size), render_scale=float(render_scale), gi_size=tuple(gi.size),
        target_fps=float(scaler.settings.target_fps), motion=still.state, frame_counts=tuple(still.counts.items()),
        model_path=gi.model.path if gi.model is not None else None, candidates=tuple(candidates),
        gi_sizes=gi.offered(), gi_note=gi.note, neural=neural is not None,
        pipelined=neural is not None and neural.pipelined, latency_ms=neural.latency_ms if neural is not None else 0.0,
        inline_direct=neural is not None and neural.inline_direct, unavailable=tuple(unavailable.items()),
        reference_available=reference.available, reference_status=reference.status() if reference_shown else "",
        reference_ready=latest is not None, gl_renderer=gl_renderer, timing_method=timer.method,
        timer_sync=timer.enabled)
