"""A light's shadow map for one frame, typed by the light's kind: each binds its lookup to a program (direct.glsl's
code: the direct pass, the inline direct light, VXGI's injection) on texture unit 4."""

from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np

from diviewer.gl.resources import set_uniform

SHADOW_UNIT = 4
"""The texture unit a shadow map is bound to."""


@dataclass(frozen=True, eq=False)
class DirectionalShadow:
    """A sun's map: a depth texture compared in hardware, of ``size`` texels a side, over the light-space box
    ``m_light`` fits around the scene (`shadow_fit.fit_directional`)."""

    map: moderngl.Texture
    m_light: np.ndarray
    texel_world: float
    """A texel's larger side, in world units (the lookup's biases scale with it)."""
    depth_range: float
    size: int
    footprint: bool
    """It holds only what can shade the view of ``clip`` (`shadow_fit.sun_footprint`)."""
    clip: np.ndarray
    """The camera's world-to-clip matrix of the frame it was drawn for."""

    def pending(self, full: int) -> bool:
        """Whether it is not yet the map drawn at rest (another size than ``full``, or cut to a view)."""
        return self.size != full or self.footprint

    def bind(self, prog) -> None:
        self.map.use(location=SHADOW_UNIT)
        for key, value in (("u_shadow_map", SHADOW_UNIT), ("m_light", self.m_light),
                           ("u_texel_world", float(self.texel_world)), ("u_depth_range", float(self.depth_range))):
            set_uniform(prog, key, value)


@dataclass(frozen=True, eq=False)
class PointShadow:
    """A point light's map: a 3 x 2 atlas of its cube faces (``faces``: their world-to-clip matrices), each
    ``face_size`` texels a side, holding distances."""

    map: moderngl.Texture
    faces: np.ndarray
    face_size: int
    size = None
    """A point light's atlas has one size: never drawn smaller while the light moves."""
    footprint = False

    def pending(self, full: int) -> bool:
        return False

    def bind(self, prog) -> None:
        self.map.use(location=SHADOW_UNIT)
        for key, value in (("u_shadow_atlas", SHADOW_UNIT), ("m_faces", self.faces),
                           ("u_face_size", float(self.face_size))):
            set_uniform(prog, key, value)
