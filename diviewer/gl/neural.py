"""The per-frame neural GI pass: pack the G-buffer on the GPU, one read-back, onnxruntime, one upload."""

from __future__ import annotations

import moderngl
import numpy as np

from diviewer.encoding import INPUT_CHANNEL_COUNT, INPUT_CHANNELS, INPUT_NAMES, input_channel_slices
from diviewer.gl.renderer import Renderer
from diviewer.gl.resources import set_uniform
from diviewer.timing import StageTimer

PACK_DEFINES = {
    "IN_CHANNELS": INPUT_CHANNEL_COUNT,
    **{f"IN_{name.upper()}": s.start for name, s in input_channel_slices().items()},
    **{f"IN_{name.upper()}_N": n for name, n in INPUT_CHANNELS},
}
"""The channel layout as pack.glsl reads it, from the encoding's table: the total, where each buffer
starts, and its component count (which the shader checks against what it writes, at compile time)."""

STAGES = ("readback", "inference", "upload")
"""The pass's stages, timed by the wall clock: the read-back waits for the GPU, so it is honest without a sync."""


class NeuralPass:
    """Runs a model (diviewer.runtime.NeuralGI) on a Renderer's buffers; the result is a GL texture.

    Per frame it makes exactly one GPU->CPU copy (the packed buffer, read into a preallocated
    array) and one CPU->GPU copy (the model's output into ``self.texture``); the model's input and
    output layouts are the arrays' own, so nothing is transposed on the CPU. The texture holds
    rows top first: display it with ``flip_y`` (the display pass does). Its stages go to the
    renderer's timer unless given one.
    """

    def __init__(self, ctx: moderngl.Context, renderer: Renderer, model, timer: StageTimer | None = None):
        self.ctx, self.renderer, self.model = ctx, renderer, model
        self.timer = timer or renderer.timer
        model.check_size(renderer.width, renderer.height)
        self.program = renderer.shaders.compute("pack.glsl", PACK_DEFINES)
        w, h = renderer.width, renderer.height
        self.packed = np.empty((1, h, w, INPUT_CHANNEL_COUNT), np.float32)
        self.ssbo = ctx.buffer(reserve=self.packed.nbytes)
        self.texture = ctx.texture((w, h), 3, dtype="f4")
        self.texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.texture.repeat_x = self.texture.repeat_y = False
        self.output: np.ndarray | None = None
        self.timings: dict[str, float] = {}
        """The last run's stage times (ms), also added to ``timer``."""
        self.copies = {"download_bytes": self.packed.nbytes, "upload_bytes": 0}

    def run(self) -> moderngl.Texture:
        """Infer the GI image from the renderer's current textures (call after renderer.render)."""
        r = self.renderer
        before = {k: self.timer.times.get(k, 0.0) for k in STAGES}
        with self.timer.stage("readback"):
            for i, name in enumerate(INPUT_NAMES):
                r.textures[name].use(location=i)
                set_uniform(self.program, f"u_{name}", i)
            set_uniform(self.program, "u_size", (r.width, r.height))
            self.ssbo.bind_to_storage_buffer(0)
            self.program.run((r.width + 7) // 8, (r.height + 7) // 8, 1)
            self.ctx.memory_barrier(moderngl.BUFFER_UPDATE_BARRIER_BIT)
            self.ssbo.read_into(self.packed)
        self.output = self.model.run(self.packed, timer=self.timer)  # the runtime times "inference"
        with self.timer.stage("upload"):
            self.texture.write(self.output)  # (1, H, W, 3) float32, contiguous: uploaded as is
        self.copies["upload_bytes"] = self.output.nbytes
        self.timings = {k: self.timer.times.get(k, 0.0) - before[k] for k in STAGES}
        return self.texture

    def image(self) -> np.ndarray:
        """The last output as (H, W, 3) float32 linear radiance, top row first."""
        if self.output is None:
            raise RuntimeError("NeuralPass.run has not been called")
        return self.output[0]

    def release(self) -> None:
        self.ssbo.release()
        self.texture.release()
