"""The viewer's settings (``ViewerSettings``) and the render scale they open with (no GL calls)."""

from __future__ import annotations

from dataclasses import dataclass, field

from diviewer.errors import DiviewerError
from diviewer.gl.neural import GISettings
from diviewer.gl.renderer import RenderSettings
from diviewer.gl.shadow_fit import MOVING_SHADOW_SIZE
from diviewer.reference.progressive import ReferenceSettings
from diviewer.viewer.scale import DEFAULT_FLOOR, MAX_SCALE
from diviewer.viewer.still import StillSettings

BACKGROUND = (0.08, 0.08, 0.09)
"""Colour of the bars around the GI image when the window's aspect ratio differs."""


def check_render_scale(scale: float) -> float:
    """A render scale the viewer can draw at: in (0, 2] (above 1: supersampled); else the user's error."""
    if not 0.0 < float(scale) <= MAX_SCALE:
        raise DiviewerError(f"render scale must be in (0, {MAX_SCALE:g}] (shaded pixels per window pixel per side; "
                            f"above 1 supersamples), got {scale}", field="--render-scale")
    return float(scale)


def scale_settings(settings: "ViewerSettings"):
    """The dynamic-resolution controller's settings for a session: a fixed ``render_scale`` turns it off."""
    from diviewer.viewer.scale import ScaleSettings

    if settings.render_scale is not None:
        scale = check_render_scale(settings.render_scale)
        return ScaleSettings(target_fps=0.0, start=scale, floor=min(settings.scale_floor, scale),
                             ceiling=min(max(settings.scale_ceiling, scale), MAX_SCALE))
    return ScaleSettings(target_fps=max(float(settings.target_fps), 0.0), floor=settings.scale_floor,
                         ceiling=settings.scale_ceiling)


@dataclass(frozen=True)
class ViewerSettings:
    """Settings a viewer session opens with (the GI resolution, pipelining and timing then change live:
    ``Viewer.gi`` and ``Viewer.timer`` hold the current ones)."""

    size: tuple[int, int] = (768, 768)
    """Window size in screen units (the framebuffer may be larger on HiDPI screens)."""
    vsync: bool = True
    model: str = "auto"
    """A model file, ``auto`` (the first compatible assets/models/<scene>*.onnx) or ``none``."""
    provider: str | None = None
    """onnxruntime execution provider (cpu, cuda, tensorrt); None picks the fastest available."""
    controller: str = "fly"
    """Camera controller at start: fly or orbit."""
    timing: bool = True
    """Time each stage: GL stages by GPU timer queries read once the frame is swapped (by waiting for the GPU around
    them where the driver has none), the rest by the wall clock."""
    gi_res: str = "model"
    """The neural GI's resolution: ``model`` (its training size), a fraction of the window (``1/4``: snapped
    to the model's stride) or ``WxH`` (a multiple of the stride, else refused)."""
    target_fps: float = 30.0
    """Frame rate the render scale is moved to hold (dynamic resolution); 0 keeps ``render_scale``."""
    render_scale: float | None = None
    """A fixed render scale (shading resolution / window, per side; above 1 supersampled, 2 at most), which turns
    ``target_fps`` off; None: 1 at the start, then whatever holds the frame rate."""
    scale_floor: float = DEFAULT_FLOOR
    """The lowest render scale dynamic resolution goes to."""
    scale_ceiling: float = 1.0
    """The highest render scale dynamic resolution goes to (up to 2: supersampling where the frame rate allows)."""
    auto_exposure: bool | None = None
    """Start with the exposure metered from the frame (the panel toggles it); None: as the scene file says
    (``[scene] auto_exposure``)."""
    gi: GISettings = field(default_factory=GISettings)
    """How the GI inputs are reduced, the output upsampled, and whether inference runs one frame behind."""
    panel: bool = True
    render: RenderSettings = field(default_factory=RenderSettings)
    moving_shadow_size: int | None = MOVING_SHADOW_SIZE
    """The sun's shadow map while it moves (Sponza's full map, 8192 texels a side, takes ~325 ms to render on a
    2-core software rasterizer), the scene's full size again once it rests; None: always full."""
    rest_in_bands: bool = True
    """At rest, the full map is drawn in bands over the next frames, each as many texels as the moving map, the
    moving map shown until the last (``Renderer.rest_in_bands``): no frame stalls when the sun stops."""
    back_faces: bool = False
    """Draw the back faces of single-sided materials in the G-buffer too, as the path tracer sees them (Sponza's
    G-buffer then takes a third longer: docs/speed.md); by default they are culled (``Renderer.back_faces``)."""
    reference: ReferenceSettings = field(default_factory=ReferenceSettings)
    reference_max_size: int = 512
    """Longest side of the path-traced reference (it is scaled to the view)."""
    title: str = "diviewer"
    path: str | None = None
    """A camera path file to play from the first frame (``--path``)."""
    record_path: str | None = None
    """Record the camera path from the first frame to the last into this file (``--record-path``)."""
    fixed_step: float | None = None
    """Seconds each frame advances the clock (animations, paths, recordings) instead of the wall clock's."""
    still: StillSettings = field(default_factory=StillSettings)
    """A view that stops changing is drawn at scale 1 (or the ceiling above 1), then presented without drawing."""
    temporal: bool = False
    """Temporal upsampling of the final image while it moves (jittered frames accumulated at the window's size,
    gl/temporal.py); a still view is refined at full scale either way."""
