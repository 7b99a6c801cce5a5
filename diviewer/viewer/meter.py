"""Auto exposure's GL side: samples of the shown radiance image on a fixed grid (shaders/meter.glsl), read back."""

from __future__ import annotations

import moderngl
import numpy as np

from diviewer.gl.resources import set_uniform
from diviewer.gl.shaders import ShaderCache

METER = 64
"""Samples per side of the grid (64 x 64 texels whatever the image's size)."""


class Meter:
    """Reads ``METER`` x ``METER`` RGB samples of a texture: one small dispatch and a 48 KB read-back."""

    def __init__(self, ctx: moderngl.Context, shaders: ShaderCache):
        self.ctx = ctx
        self.program = shaders.compute("meter.glsl", {"METER": METER})
        self.samples = np.empty((METER, METER, 3), np.float32)
        self.buffer = ctx.buffer(reserve=self.samples.nbytes)

    def read(self, texture: moderngl.Texture) -> np.ndarray:
        """The samples of ``texture`` (its first three channels), (METER, METER, 3) float32."""
        texture.use(location=0)
        set_uniform(self.program, "u_image", 0)
        self.buffer.bind_to_storage_buffer(0)
        self.program.run((METER + 7) // 8, (METER + 7) // 8, 1)
        self.ctx.memory_barrier(moderngl.BUFFER_UPDATE_BARRIER_BIT)
        self.buffer.read_into(self.samples)
        return self.samples

    def release(self) -> None:
        self.buffer.release()
