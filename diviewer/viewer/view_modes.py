"""The view modes: what the viewer's window can show (final, direct, reference, G-buffers, split, difference).

A mode says where its image comes from (``produce``, from a frame's ``FrameSources``) and how its values
become pixels (``display``, one of the display pass's kinds). Pure data: no GL.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from diviewer.errors import DiviewerError


class Unavailable(Exception):
    """A view mode's image cannot be produced now; the message says why (shown in the panel)."""


class FrameSources(Protocol):
    """What a view mode draws from; the app implements it (the images are GL textures there)."""

    has_model: bool

    def buffer(self, name: str) -> Any:
        """A G-buffer channel of this frame: depth, normal, albedo, direct."""

    def network_output(self) -> Any:
        """The model's output for this frame at the GI resolution (raises Unavailable without a model)."""

    def final(self) -> Any:
        """The full-resolution frame with the model's indirect light upsampled into it (needs a model)."""

    def reference(self) -> Any:
        """The latest path-traced reference of this view (raises Unavailable while none is ready)."""

    def vxgi(self) -> Any:
        """This frame through voxel cone tracing (diviewer.gl.vxgi): direct + albedo x indirect."""


@dataclass(frozen=True)
class ViewMode:
    """One entry of the view-mode registry: what the window shows and how to produce it."""

    name: str
    label: str
    produce: Callable[[FrameSources], Any] | None
    """Gets the image from the frame's sources; None for the two-image layouts (split, difference)."""
    display: str = "radiance"
    """How values become pixels: radiance (exposure + tone map), raw (linear clamped to [0, 1]),
    depth (near bright, far dark), normal (n / 2 + 1/2), albedo (sRGB of the linear value)."""
    layout: str = "single"
    """single, split (A left, B right) or difference (|A - B|)."""
    key: str = ""
    """Keyboard shortcut."""
    help: str = ""


def _final(s: FrameSources):
    # The full-resolution direct light plus the model's indirect light (its output less its input direct
    # light) upsampled from the GI resolution; without a model the frame has direct light only.
    return s.final() if s.has_model else s.buffer("direct")


VIEW_MODES: tuple[ViewMode, ...] = (
    ViewMode("final", "Final (neural GI)", _final, "radiance", key="1",
             help="full-resolution direct light + the network's indirect light, upsampled edge-aware from the "
                  "GI resolution (direct light only when no model is loaded)"),
    ViewMode("direct", "Direct light only", lambda s: s.buffer("direct"), "radiance", key="2",
             help="the GL renderer's shadow-mapped direct light and emission"),
    ViewMode("reference", "Path-traced reference", lambda s: s.reference(), "radiance", key="3",
             help="Mitsuba 3, rendered progressively in the background; restarts when anything changes"),
    ViewMode("vxgi", "VXGI (voxel cone tracing)", lambda s: s.vxgi(), "radiance",
             help="direct light + one bounce of indirect light traced through a voxel grid; no network"),
    ViewMode("depth", "G-buffer: depth", lambda s: s.buffer("depth"), "depth", key="4"),
    ViewMode("normal", "G-buffer: normal", lambda s: s.buffer("normal"), "normal", key="5",
             help="view-space normals"),
    ViewMode("albedo", "G-buffer: albedo", lambda s: s.buffer("albedo"), "albedo", key="6"),
    ViewMode("net_input", "Network input: direct (raw)", lambda s: s.buffer("direct"), "raw", key="7",
             help="the direct-light channel the network reads, linear values clamped to [0, 1]"),
    ViewMode("net_output", "Network output: raw GI", lambda s: s.network_output(), "raw", key="8",
             help="the network's output at the GI resolution, linear values clamped to [0, 1]"),
    ViewMode("split", "Split screen (A | B)", None, layout="split", key="9",
             help="mode A left of the divider, mode B right of it"),
    ViewMode("difference", "Difference |A - B|", None, layout="difference", key="0",
             help="absolute difference of modes A and B, with a gain"),
)
"""All view modes, in panel order; adding one (VXGI) is one entry here plus its source in the app."""

VIEW_MODE_NAMES = tuple(m.name for m in VIEW_MODES)


def view_mode(name: str) -> ViewMode:
    for m in VIEW_MODES:
        if m.name == name:
            return m
    raise DiviewerError(f"unknown view mode '{name}'; view modes: {', '.join(VIEW_MODE_NAMES)}", field="view mode")


def produce(mode: ViewMode, sources: FrameSources) -> Any:
    """The image of single-image ``mode`` from this frame's ``sources``; Unavailable propagates with the reason."""
    if mode.produce is None:
        raise DiviewerError(f"view mode '{mode.name}' combines two modes: produce those", field="view mode")
    return mode.produce(sources)


def single_modes() -> tuple[ViewMode, ...]:
    """The modes that show one image (those split screen and difference combine)."""
    return tuple(m for m in VIEW_MODES if m.layout == "single")
