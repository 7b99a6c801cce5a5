"""The GI pass below frame resolution: its indirect light, bilinearly upsampled, over the frame's own direct light."""

from __future__ import annotations

import moderngl

from diviewer.gl.context import unbind_framebuffer
from diviewer.gl.neural import NeuralPass
from diviewer.gl.resources import set_uniform


class UpsamplePass:
    """Adds a low-resolution NeuralPass's indirect light (``step`` > 1) to the renderer's direct light.

    The result is a frame-sized float texture with rows bottom first, like the renderer's buffers.
    Timed as the ``upsample`` stage of the neural pass's timer.
    """

    def __init__(self, ctx: moderngl.Context, neural: NeuralPass):
        if neural.step == 1:
            raise ValueError("UpsamplePass needs a NeuralPass below frame resolution (step > 1)")
        self.ctx, self.neural, self.renderer = ctx, neural, neural.renderer
        self.program = self.renderer.shaders.program("upsample.glsl")
        size = (self.renderer.width, self.renderer.height)
        self.texture = ctx.texture(size, 4, dtype="f4")
        self.texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.fbo = ctx.framebuffer([self.texture])
        self.vao = ctx.vertex_array(self.program, [])

    def run(self) -> moderngl.Texture:
        """Upsample the neural pass's last output (call after ``neural.run``)."""
        with self.neural.timer.stage("upsample", gpu=True):
            self.fbo.use()
            self.ctx.enable_only(moderngl.NOTHING)
            self.renderer.textures["direct"].use(location=0)
            self.neural.texture.use(location=1)
            set_uniform(self.program, "u_direct", 0)
            set_uniform(self.program, "u_indirect", 1)
            self.vao.render(moderngl.TRIANGLES, vertices=3)
        return self.texture

    def release(self) -> None:
        unbind_framebuffer(self.ctx)
        for r in (self.vao, self.fbo, self.texture):
            r.release()
