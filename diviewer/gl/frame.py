"""A frame's buffers: what the renderer returns (`Renderer.buffers`) and everything that feeds the network reads.

A `Frame` names the four input textures (depth, normal, albedo, direct) of one rendered frame at its size, and
records how its direct light was made, decided once per frame:

- ``pass``: the renderer's direct pass drew it into the direct target;
- ``inline``: the pass was deferred and the frame has at most one light, so whoever reads the buffers computes
  each pixel's direct light itself (shaders/direct_inline.glsl): ``direct`` is then the emission buffer and
  `bind` also sets the light's uniforms and shadow map;
- ``area``: drawn by the direct pass at ``samples`` x ``samples`` times the size of the frame it stands for, to be
  averaged over each pixel's block (`diviewer.gl.area`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import moderngl

from diviewer.gl.resources import set_uniform
from diviewer.gl.shadow_fit import light_defines

DIRECT_FROM = ("pass", "inline", "area")
"""How a frame's direct light was made (`Frame.direct_from`)."""

NAMES = ("depth", "normal", "albedo", "direct")
"""The frame's textures, in the network's input order; texture units 0-3 in `Frame.bind`."""


@dataclass(frozen=True)
class Frame:
    """One rendered frame's buffers on the GPU and how its direct light was made. Its textures are the renderer's
    targets: valid until the renderer draws its next frame (``view`` says which frame it is)."""

    size: tuple[int, int]
    """(width, height) of the textures."""
    depth: moderngl.Texture
    normal: moderngl.Texture
    albedo: moderngl.Texture
    direct: moderngl.Texture
    """The direct light (``pass``, ``area``), or the emission buffer the inline light is added to (``inline``)."""
    direct_from: str = "pass"
    """``pass``, ``inline`` or ``area`` (`DIRECT_FROM`)."""
    samples: int = 1
    """``area``: samples per axis of the frame it stands for (the textures are that many times its size); else 1."""
    light: Any = None
    """``inline``: the frame's one light (None: it has none)."""
    emissive: bool = False
    """Whether a material of the scene emits (``inline`` adds the emission buffer)."""
    view: Any = None
    """The renderer's `FrameView` of this frame: its identity."""
    light_uniforms: Callable[[Any, Any], None] | None = field(default=None, compare=False, repr=False)
    """``inline``: sets the light's uniforms and shadow map on a program (`Renderer.set_direct_uniforms`)."""

    def __post_init__(self):
        if self.direct_from not in DIRECT_FROM:
            raise ValueError(f"direct_from: one of {', '.join(DIRECT_FROM)}, got {self.direct_from!r}")
        if (self.samples > 1) != (self.direct_from == "area"):
            raise ValueError(f"an {self.direct_from} frame has {'more than one' if self.samples > 1 else 'one'} "
                             "sample per axis")

    @property
    def inline(self) -> bool:
        """Whether the reader computes the direct light itself (``direct_from == "inline"``)."""
        return self.direct_from == "inline"

    @property
    def textures(self) -> dict[str, moderngl.Texture]:
        """The four textures by name (`NAMES`)."""
        return {name: getattr(self, name) for name in NAMES}

    def defines(self) -> dict[str, int]:
        """The shader defines of this frame's direct light: those of direct_inline.glsl's light for ``inline``
        (its kind, EMISSIVE where the scene emits), none otherwise."""
        if not self.inline:
            return {}
        return {"INLINE_DIRECT": 1, **light_defines(self.light), **({"EMISSIVE": 1} if self.emissive else {})}

    def bind(self, prog) -> None:
        """Units 0-3: depth, normal, albedo and direct (``u_depth`` ... ``u_direct``; ``u_emission`` for the fourth
        when ``inline``, with the light's uniforms and its shadow map on unit 4)."""
        fourth = "emission" if self.inline else "direct"
        for i, (name, tex) in enumerate(zip(("depth", "normal", "albedo", fourth),
                                            (self.depth, self.normal, self.albedo, self.direct))):
            tex.use(location=i)
            set_uniform(prog, f"u_{name}", i)
        if self.inline and self.light is not None:
            self.light_uniforms(prog, self.light)
