"""Temporal upsampling: jittered frames at the shading resolution accumulated at the window's (shaders/temporal.glsl).

Karis, "High-quality temporal supersampling" (SIGGRAPH 2014) and AMD FSR 2: each frame the G-buffer's projection
moves by the next offset of a Halton(2, 3) sequence (``Renderer.jitter``); the resolve reprojects the history by the
G-buffer's motion vectors where the frame has them (``Renderer.velocity``, gl/motion.py: each surface's motion from
its object's previous pose and the previous camera, the jitter left out; a pixel takes the nearest surface's of its
3x3 neighbourhood, so that a moving object's edge keeps its history), else, and for the sky, by the depth and the
camera's motion (the previous frame's view and projection); clamps it to the current frame's 3x3 neighbourhood colour
box (YCoCg); drops it where the history's depth, moved back by the point's own change of depth, disagrees with the
neighbourhood's (disocclusion); and blends in the current sample nearest each window pixel, weighted by its distance.
The output is a radiance texture at the window's size, which the display pass then shows.
"""

from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np

from diviewer.gl.resources import set_uniform
from diviewer.gl.shaders import ShaderCache
from diviewer.scene.camera import halton


@dataclass(frozen=True)
class TemporalSettings:
    """How jittered frames are accumulated."""

    phases: int = 8
    """Length of the Halton(2, 3) jitter sequence at scale 1; at scale ``s`` it is ``phases / s^2`` (FSR 2's rule:
    as many samples per window pixel at every scale)."""
    max_weight: float = 1.0
    """While the view moves, the history's weight is capped at this many frames' worth (``max_weight * s^2`` in units
    of one sample at a pixel's centre, a frame at scale ``s`` adding about ``s^2``): the longer, the smoother and
    the slower to follow a change inside the colour box (cornell, light moving, scale 0.4: 1 scored best of 1, 2 and
    4, docs/viewer.md). At rest it is capped at ``rest_cycles`` cycles of the
    sequence (an average of them)."""
    rest_cycles: int = 2
    """Cycles of the jitter sequence a resting view averages (and accumulates before it counts as converged)."""
    sigma: float = 0.47
    """Width (window pixels) of the Gaussian that weights the current sample by its distance to the pixel."""
    gamma: float = 1.0
    """Variance clipping (Salvi 2016): the neighbourhood's colour box is narrowed to its mean +- this many standard
    deviations (within its min and max) before the history is clamped to it; a resting view clamps to the min and
    max alone (nothing changes there but the jitter)."""
    depth_tolerance: float = 0.05
    """Relative depth mismatch at which the reprojected history is dropped (disocclusion)."""


def jitter_phases(settings: TemporalSettings, scale: float) -> int:
    """The jitter sequence's length for frames drawn at ``scale`` of the window's size per side."""
    return max(settings.phases, round(settings.phases / max(scale, 1e-3) ** 2))


def jitter_offset(frame: int, phases: int) -> tuple[float, float]:
    """The sub-pixel offset (pixels, in [-0.5, 0.5)) of frame ``frame``: Halton(2, 3) from its second element."""
    k = frame % phases + 1
    return halton(k, 2) - 0.5, halton(k, 3) - 0.5


class TemporalPass:
    """The resolve's program, its history (two ping-ponged targets at the window's size) and the last camera."""

    def __init__(self, ctx: moderngl.Context, shaders: ShaderCache, settings: TemporalSettings = TemporalSettings()):
        self.ctx, self.settings = ctx, settings
        self.prog = shaders.program("temporal.glsl")
        self.vao = ctx.vertex_array(self.prog, [])
        self._targets: list[tuple[moderngl.Texture, moderngl.Texture, moderngl.Framebuffer]] = []
        self._size: tuple[int, int] | None = None
        self._prev: np.ndarray | None = None
        """The last resolved frame's view and projection (unjittered), (2, 4, 4)."""
        self._index = 0
        self.frames = 0
        """Frames accumulated since the history was last dropped."""
        self.phases = settings.phases
        """The jitter sequence's length at the scale of the last frame asked for (``jitter``)."""

    def jitter(self, scale: float = 1.0) -> tuple[float, float]:
        """The offset the next frame's G-buffer, drawn at ``scale`` of the window's size, is drawn with
        (``Renderer.jitter``)."""
        self.phases = jitter_phases(self.settings, scale)
        return jitter_offset(self._index, self.phases)

    @property
    def converged(self) -> bool:
        """Whether a resting view has accumulated its ``rest_cycles`` cycles of the jitter sequence."""
        return self.frames >= self.settings.rest_cycles * self.phases

    def reset(self) -> None:
        """Drop the history (the next resolve shows the current frame alone)."""
        self._prev, self.frames = None, 0

    def _ensure(self, size: tuple[int, int]) -> None:
        if self._size == size:
            return
        self._release_targets()
        for _ in range(2):
            color = self.ctx.texture(size, 4, dtype="f4")
            color.filter = (moderngl.LINEAR, moderngl.LINEAR)
            depth = self.ctx.texture(size, 1, dtype="f4")
            depth.filter = (moderngl.NEAREST, moderngl.NEAREST)
            for t in (color, depth):
                t.repeat_x = t.repeat_y = False
            self._targets.append((color, depth, self.ctx.framebuffer([color, depth])))
        self._size = size
        self.reset()

    def resolve(self, current: moderngl.Texture, depth: moderngl.Texture, size: tuple[int, int],
                jitter: tuple[float, float], view: np.ndarray, proj: np.ndarray, resting: bool = False,
                velocity: moderngl.Texture | None = None) -> moderngl.Texture:
        """Blend ``current`` (drawn with ``jitter``, its linear ``depth``) into the history at ``size``; returns
        the new history's radiance (rgb; alpha: its weight). ``view``, ``proj``: the frame's, unjittered;
        ``resting``: nothing changed since the last frame (the history's weight may grow to an average);
        ``velocity``: the frame's motion vectors (``Renderer.velocity``), which then reproject its surfaces."""
        self._ensure(size)
        out_color, out_depth, fbo = self._targets[self._index % 2]
        hist_color, hist_depth, _ = self._targets[(self._index + 1) % 2]
        s, prog = self.settings, self.prog
        has = self._prev is not None
        inv_view = np.linalg.inv(view)
        prev_view, prev_proj = (self._prev[0], self._prev[1]) if has else (view, proj)
        for unit, tex in enumerate((current, depth, hist_color, hist_depth, velocity)):
            if tex is not None:
                tex.use(location=unit)
        # A frame at scale s adds about s^2 of weight per window pixel: the cap in motion counts frames, not samples.
        scale = min(current.width / size[0], 1.0)
        cap = s.rest_cycles * self.phases if resting else s.max_weight * scale * scale
        for name, value in (("u_current", 0), ("u_depth", 1), ("u_history", 2), ("u_history_depth", 3),
                            ("u_velocity", 4), ("u_has_velocity", velocity is not None),
                            ("u_jitter", tuple(map(float, jitter))),
                            ("u_inv_focal", (1.0 / float(proj[0, 0]), 1.0 / float(proj[1, 1]))),
                            ("m_reproj", prev_proj @ prev_view @ inv_view), ("m_prev_view", prev_view @ inv_view),
                            ("u_has_history", has), ("u_max_weight", float(cap)),
                            ("u_sigma", float(s.sigma)), ("u_gamma", 1e6 if resting else float(s.gamma)),
                            ("u_depth_tolerance", float(s.depth_tolerance))):
            set_uniform(prog, name, value)
        fbo.use()
        fbo.viewport = (0, 0, *size)
        self.ctx.disable(moderngl.BLEND | moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        self.vao.render(moderngl.TRIANGLES, vertices=3)
        self._prev = np.stack([np.asarray(view, np.float64), np.asarray(proj, np.float64)])
        self._index += 1
        self.frames += 1
        return out_color

    def _release_targets(self) -> None:
        for color, depth, fbo in self._targets:
            fbo.release()
            color.release()
            depth.release()
        self._targets, self._size = [], None

    def release(self) -> None:
        self._release_targets()
        self.vao.release()
