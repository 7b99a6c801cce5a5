"""The GL side of a model's lean path (`diviewer.contract.lean`): encode.glsl encodes the inputs pack.glsl wrote into the
network's padded input on the GPU (one read-back, of the encoded tensor), onnxruntime runs the generator alone,
decode.glsl decodes its raw output into the radiance texture the rest of the neural pass reads
(`diviewer.gl.neural.NeuralPass`)."""

from __future__ import annotations

import moderngl
import numpy as np

from diviewer.gl.resources import set_uniform


class LeanIO:
    """The encoded inputs (two slots, as the pass's raw inputs), the raw output's buffer, the encode and decode
    programs."""

    def __init__(self, ctx: moderngl.Context, shaders, model, gi_size: tuple[int, int], pack_defines: dict):
        self.ctx, self.model = ctx, model
        w, h = gi_size
        (pw, ph), self.pad = model.padding(w, h)
        self.padded = (pw, ph)
        enc = model.enc
        defines = dict(pack_defines, **({"WORLD": 1} if enc.world_inputs else {}),
                       **({"LIGHTS": model.light_count} if enc.light_inputs else {}))
        self.encode_program = shaders.compute("encode.glsl", defines)
        self.encoded = [np.empty((1, model.planes, ph, pw), np.float32) for _ in range(2)]
        self.buffers = [ctx.buffer(reserve=self.encoded[0].nbytes) for _ in range(2)]
        self.raw = ctx.buffer(reserve=3 * ph * pw * 4)
        self.constants: list[dict | None] = [None, None]
        decode_defines = dict(pack_defines, **({"FULL": 1} if model.target == "full" else {}),
                              **({"DIVIDE_ALBEDO": 1} if model.divide_albedo else {}))
        self.decode = shaders.compute("decode.glsl", decode_defines)

    def set_frame(self, slot: int, width: int, height: int, light_scale=None, camera=None, light=None) -> None:
        """The frame's constants (`diviewer.contract.lean.LeanModel.constants`) for the slot it is packed into."""
        self.constants[slot] = self.model.constants(width, height, light_scale, camera, light)

    def encode(self, slot: int, packed: moderngl.Buffer, gi_size: tuple[int, int]) -> None:
        """Encode the slot's raw inputs (``packed``, written by pack.glsl) over the padded size; read them back."""
        k, enc, prog = self.constants[slot], self.model.enc, self.encode_program
        packed.bind_to_storage_buffer(0)
        self.buffers[slot].bind_to_storage_buffer(1)
        for name, value in (("u_size", gi_size), ("u_padded", self.padded), ("u_pad", self.pad),
                            ("u_in_k", float(k["in_k"])),
                            ("u_depth_inv", float(np.float32(1.0 / enc.depth_scale))),
                            ("u_radiance_max", float(enc.radiance_max)), ("u_log_r", float(self.model.log_r))):
            set_uniform(prog, name, value)
        if enc.world_inputs:
            set_uniform(prog, "u_camera", tuple(float(v) for v in k["camera"]))
            set_uniform(prog, "u_world_center", tuple(float(v) for v in enc.world_center))
            set_uniform(prog, "u_world_inv_half", tuple(float(np.float32(1.0) / np.float32(v)) for v in enc.world_half))
        if enc.light_inputs:
            set_uniform(prog, "u_light", tuple(float(v) for v in k["light"]))
        pw, ph = self.padded
        prog.run((pw + 7) // 8, (ph + 7) // 8, 1)
        self.ctx.memory_barrier(moderngl.BUFFER_UPDATE_BARRIER_BIT | moderngl.SHADER_STORAGE_BARRIER_BIT)
        self.buffers[slot].read_into(self.encoded[slot])

    def show(self, y: np.ndarray, slot: int, packed: moderngl.Buffer, texture: moderngl.Texture) -> None:
        """Upload the generator's raw output of the slot's inputs and decode it into ``texture`` (rgba32f)."""
        self.raw.write(np.ascontiguousarray(y, np.float32))
        prog, k = self.decode, self.constants[slot]
        packed.bind_to_storage_buffer(0)
        self.raw.bind_to_storage_buffer(1)
        texture.bind_to_image(0, read=False, write=True)
        set_uniform(prog, "u_gi_size", texture.size)
        set_uniform(prog, "u_padded", self.padded)
        set_uniform(prog, "u_pad", self.pad)
        set_uniform(prog, "u_out_k", float(k["out_k"]))
        set_uniform(prog, "u_log_r", float(self.model.log_r))
        if self.model.floor_lo is not None:
            set_uniform(prog, "u_floor_lo", float(self.model.floor_lo))
        w, h = texture.size
        prog.run((w + 7) // 8, (h + 7) // 8, 1)
        self.ctx.memory_barrier()

    def release(self) -> None:
        for b in (*self.buffers, self.raw):
            b.release()
