"""Motion vectors: the G-buffer pass's velocity target, drawn for temporal upsampling only (gl/temporal.py).

Each pixel of ``velocity`` (rgba half floats) holds where its surface point lay on screen in the previous frame drawn
with motion vectors: rg the offset from its current, unjittered position to its previous one in texture coordinates
(previous = current + rg; the jitter is no motion), b the change of its linear view depth (previous - current), a 1
where a surface was drawn (the sky keeps 0). The previous position comes from each object's previous model matrix
and the previous unjittered view and projection; the first frame, and an object new since the last, take the
current ones (no motion). The objects that never move, merged into world-space chunks (gl/culling.py), have none.
"""

from __future__ import annotations

import moderngl
import numpy as np

from diviewer.scene.model import FrameConfig


class MotionVectors:
    """The velocity target with the framebuffers that add it to the G-buffer's, and the last frame's camera and
    object poses."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self.texture: moderngl.Texture | None = None
        self._fbos: dict[bool, moderngl.Framebuffer] = {}
        self._prev: tuple | None = None
        """The last frame's (unjittered view, projection, objects by name)."""
        self._objects: tuple = (None, {})
        self._before: dict = {}
        self._now: tuple | None = None
        self.drawn = False
        """Whether the last frame drew the target (``texture`` holds its motion vectors)."""

    def framebuffer(self, targets: list[moderngl.Texture], zbuffer, emissive: bool) -> moderngl.Framebuffer:
        """The G-buffer's colour ``targets`` (depth, normal, albedo[, emission]) and the velocity target after them."""
        if emissive not in self._fbos:
            size = targets[0].size
            if self.texture is None or self.texture.size != size:
                self.release()
                self.texture = self.ctx.texture(size, 4, dtype="f2")
                self.texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._fbos[emissive] = self.ctx.framebuffer([*targets, self.texture], zbuffer)
        return self._fbos[emissive]

    def begin(self, config: FrameConfig, view: np.ndarray, proj: np.ndarray):
        """Set up this frame (``view``, ``proj``: unjittered); returns its frame-wide uniforms (name -> value)."""
        if self._objects[0] is not config.objects:
            self._objects = (config.objects, {o.name: o for o in config.objects})
        prev_view, prev_proj, self._before = self._prev if self._prev is not None else (view, proj, self._objects[1])
        self._now = (view, proj, self._objects[1])
        return {"m_proj_unjittered": proj, "m_prev_view": prev_view, "m_prev_proj": prev_proj}

    def previous_model(self, name: str | None, model: np.ndarray) -> np.ndarray:
        """The previous model matrix of the object ``name`` drawn now with ``model`` (None: merged world-space
        geometry, which never moves); an object new since the last frame: ``model``."""
        if name is None:
            return model
        before, now = self._before.get(name), self._now[2].get(name)
        return model if before is None or before == now else before.matrix()

    def end(self) -> None:
        """This frame, drawn, becomes the previous one."""
        self._prev, self._now, self.drawn = self._now, None, True

    def forget(self) -> None:
        """A frame drawn without the target: the next one drawn with it has no previous frame."""
        self._prev, self.drawn = None, False

    def release(self) -> None:
        for fbo in self._fbos.values():
            fbo.release()
        self._fbos = {}
        if self.texture is not None:
            self.texture.release()
            self.texture = None
