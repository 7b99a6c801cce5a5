"""The per-frame neural GI pass: downsample and pack the G-buffer on the GPU, one read-back, onnxruntime,
one upload, then the joint bilateral upsample of the indirect light over the full-resolution frame.

The renderer draws at the window's resolution; the network runs at the GI resolution (its own, or a
fraction of the window's). ``pack.glsl`` reduces each full-resolution buffer to the GI grid while
packing it into the model's NHWC input; ``upsample.glsl`` turns the network's output back into a
full-resolution image (direct light at full resolution + upsampled indirect light). With
``pipelined`` the network runs on a worker thread one frame behind: frame N's inputs are packed and
handed over while frame N-1's output is composited, so GL and onnxruntime overlap.

A lean model (`diviewer.contract.lean.LeanModel`) runs its generator alone: an encode pass turns the packed inputs into the
network's padded input (read back instead of the raw buffers) and a decode pass turns the generator's raw output into the same
radiance texture (`diviewer.gl.lean`); the ``readback`` stage then holds the encode pass, the ``upload`` stage
the upload and the decode's dispatch.
"""

from __future__ import annotations

import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass

import moderngl
import numpy as np

from diviewer.contract.encoding import INPUT_CHANNEL_COUNT, INPUT_CHANNELS, input_channel_slices
from diviewer.errors import DiviewerError
from diviewer.gl.context import unbind_framebuffer
from diviewer.gl.frame import Frame
from diviewer.gl.renderer import Renderer
from diviewer.gl.resources import set_uniform
from diviewer.timing import StageTimer

PACK_DEFINES = {
    "IN_CHANNELS": INPUT_CHANNEL_COUNT,
    **{f"IN_{name.upper()}": s.start for name, s in input_channel_slices().items()},
    **{f"IN_{name.upper()}_N": n for name, n in INPUT_CHANNELS},
}
"""The channel layout as pack.glsl and upsample.glsl read it, from the encoding's table: the total, where
each buffer starts, and its component count (which pack.glsl checks against what it writes)."""

STAGES = ("readback", "inference", "inference_wait", "upload", "upsample")
"""The pass's stages. readback/inference/upload by the wall clock (the read-back waits for the GPU, so it
is honest without a sync; pipelined, ``inference`` is the worker's time for the prediction shown and
``inference_wait`` what the frame waited for it); upsample is GL work, timed as the timer times GL stages."""

DOWNSAMPLES = ("nearest", "area")


@dataclass(frozen=True)
class GISettings:
    """How the neural GI pass reduces its inputs, upsamples its output and schedules the network."""

    downsample: str = "nearest"
    """``nearest``: each GI texel takes the full-resolution pixel nearest its centre, as a render at the GI
    resolution would (the training captures were rendered at the model's resolution); ``area``: the mean of
    its footprint for normal, albedo and direct (depth stays nearest). Against the path tracer at window
    resolution the two score the same to 0.02 dB (docs/viewer.md, tools/experiments/fullres_accuracy.py)."""
    depth_sigma: float = 0.1
    """Joint bilateral upsample: relative depth difference at which a GI texel's weight falls to 1/e."""
    normal_power: float = 16.0
    """Joint bilateral upsample: exponent of the cosine between the pixel's and the texel's normals."""
    pipelined: bool = False
    """Run the network on a worker thread, one frame behind (the frame shows the previous frame's GI)."""
    lean: bool = True
    """Run a model's lean path where it has one (`diviewer.contract.lean`: the generator alone in onnxruntime, its encoding
    and decoding in shaders; equal to the graph's radiance to 1e-4 of the frame's peak, tests/gl/test_lean.py); False: its whole graph."""


class NeuralPass:
    """Runs a model (diviewer.contract.runtime.NeuralGI) on a Renderer's buffers at a GI resolution; composites the result.

    Per frame it makes exactly one GPU->CPU copy (the packed GI-resolution buffer, read into a preallocated
    array that onnxruntime reads as is) and one CPU->GPU copy (the model's output into ``self.texture``).
    ``run()`` gives the network's output (GI resolution, rows top first: display it flipped);
    ``composite()`` the full-resolution frame (``self.final``). Stages go to the renderer's timer unless
    given one.
    """

    def __init__(self, ctx: moderngl.Context, renderer: Renderer, model, gi_size: tuple[int, int] | None = None,
                 settings: GISettings = GISettings(), timer: StageTimer | None = None):
        self.path_note = ""
        """Why a model runs its graph although ``settings.lean`` asks for its lean path, or empty."""
        if settings.lean and not getattr(model, "lean", False):
            from diviewer.contract.lean import lean_model

            lean, self.path_note = lean_model(model)
            model = lean if lean is not None else model
        elif not settings.lean and getattr(model, "lean", False):
            model = model.graph
        self.ctx, self.renderer, self.model, self.settings = ctx, renderer, model, settings
        self.timer = timer or renderer.timer
        if settings.downsample not in DOWNSAMPLES:
            raise DiviewerError(f"unknown GI downsample '{settings.downsample}'; use one of {', '.join(DOWNSAMPLES)}",
                                field="downsample")
        w, h = gi_size or (renderer.width, renderer.height)
        if hasattr(model, "check_size"):  # a runtime that pads any size to its stride may drop the check
            model.check_size(w, h)
        self.gi_size = (w, h)
        self._pack_defines = dict(PACK_DEFINES, **({"AREA": 1} if settings.downsample == "area" else {}))
        if int(getattr(model, "direct_samples", 1)) > 1:  # trained on the direct light over each pixel's area
            self._pack_defines["AREA_DIRECT"] = 1
        self.guide = renderer.shaders.compute("gi_guide.glsl", PACK_DEFINES)
        self._vaos: dict[int, moderngl.VertexArray] = {}
        self._defines: dict[str, int] = {}
        self.frame: Frame | None = None
        """The frame the last ``run`` read (`diviewer.gl.frame.Frame`): its buffers and how its direct light was made."""
        self._given = False
        # Two input slots: with pipelining, frame N packs into one while frame N-1's (read by the upsample,
        # which must see the inputs its output was predicted from) stays in the other.
        self._packed = [np.empty((1, h, w, INPUT_CHANNEL_COUNT), np.float32) for _ in range(2)]
        self.ssbos = [ctx.buffer(reserve=self._packed[0].nbytes) for _ in range(2)]
        self._slot = 0
        self.shown_slot = 0
        """The slot whose inputs the current ``texture`` was predicted from."""
        self.lean = None
        """The lean path's buffers and decode pass (`diviewer.gl.lean.LeanIO`), for a lean model."""
        if getattr(model, "lean", False):
            from diviewer.gl.lean import LeanIO

            self.lean = LeanIO(ctx, renderer.shaders, model, (w, h), PACK_DEFINES)
        self.texture = ctx.texture((w, h), 4 if self.lean else 3, dtype="f4")  # the decode pass writes rgba32f
        self.texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.texture.repeat_x = self.texture.repeat_y = False
        self.guides = [ctx.texture((w, h), 4, dtype="f4") for _ in range(2)]
        """Per GI texel: (indirect light / albedo, depth) and (normal, 0), made by gi_guide.glsl."""
        for t in self.guides:
            t.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.final: moderngl.Texture | None = None
        self._final_fbo: moderngl.Framebuffer | None = None
        self.output: np.ndarray | None = None
        self.timings: dict[str, float] = {}
        """The last frame's stage times (ms), also added to ``timer``."""
        self.copies = {"download_bytes": (self.lean.encoded[0] if self.lean else self._packed[0]).nbytes,
                       "upload_bytes": 0}
        self.latency_ms = 0.0
        """How old the shown GI is when composited: from its inputs' read-back to its upload (ms)."""
        self._worker: ThreadPoolExecutor | None = None
        self._inflight: tuple[Future, int, float] | None = None

    @property
    def packed(self) -> np.ndarray:
        """The inputs (1, H, W, 10) the shown prediction was made from, as the network read them (a lean model's
        are read back from the GPU here, on demand)."""
        if self.lean is not None:
            self.ssbos[self.shown_slot].read_into(self._packed[self.shown_slot])
        return self._packed[self.shown_slot]

    @property
    def inference_path(self) -> str:
        """"lean" (the generator alone, `diviewer.contract.lean`) or "graph" (the model's self-contained graph)."""
        return "lean" if self.lean is not None else "graph"

    @property
    def pipelined(self) -> bool:
        return self.settings.pipelined

    # --- the frame: its buffers and its direct light, decided once -----------------------------------
    def _frame(self, frame: Frame | None = None, again: bool = False) -> Frame:
        """The frame this pass reads (``frame``, else the renderer's last, `Renderer.buffers`), its direct light
        decided once: run() records it and composite() (``again``) reads the same frame, unless run() took the
        renderer's and the renderer drew another since.

        Where the renderer deferred its direct pass and the frame has at most one light, pack and upsample compute
        each pixel's direct light as the direct pass would have (one full-resolution pass, its target and its reads
        fewer); otherwise they read the direct pass's target. A pack that averages each GI texel's footprint (AREA,
        AREA_DIRECT) reads every pixel's direct light itself, so inline it would compute the full-resolution light
        twice (pack and upsample): it reads the direct pass's target instead (the viewer at 768x768, full
        resolution, llvmpipe: 62.6 -> 57.1 ms a frame).
        """
        given = frame is not None
        if frame is None:
            if again and self.frame is not None and (self._given or self.frame.view is self.renderer.frame_view):
                return self.frame
            footprint = "AREA" in self._pack_defines or "AREA_DIRECT" in self._pack_defines
            frame = self.renderer.buffers(inline=not footprint)
        elif frame.samples > 1 and frame.samples != int(getattr(self.model, "direct_samples", 1)):
            raise ValueError(f"the frame's direct light is over {frame.samples}x{frame.samples} samples, the model's "
                             f"over {getattr(self.model, 'direct_samples', 1)}")
        self.frame, self._given = frame, given
        self._defines = frame.defines()
        return frame

    @property
    def inline_direct(self) -> bool:
        """This frame's direct light was computed inside the pack and the upsample (direct_inline.glsl),
        not read from the renderer's direct pass (which then did not run)."""
        return self.frame is not None and self.frame.inline

    @property
    def program(self) -> moderngl.ComputeShader:
        """The pack program of the current direct-light variant."""
        return self.renderer.shaders.compute("pack.glsl", {**self._pack_defines, **self._defines})

    @property
    def upsample(self) -> moderngl.Program:
        """The upsample program of the current direct-light variant."""
        return self.renderer.shaders.program("upsample.glsl", self._defines)

    # --- the network ----------------------------------------------------------------------------
    def _pack(self, slot: int) -> None:
        prog = self.program
        self.frame.bind(prog)
        w, h = self.gi_size
        set_uniform(prog, "u_size", (w, h))
        set_uniform(prog, "u_src_size", self.frame.size)
        self.ssbos[slot].bind_to_storage_buffer(0)
        prog.run((w + 7) // 8, (h + 7) // 8, 1)
        if self.lean is not None:  # encoded on the GPU: the encoded input is what comes back
            self.ctx.memory_barrier(moderngl.SHADER_STORAGE_BARRIER_BIT)
            return self.lean.encode(slot, self.ssbos[slot], self.gi_size)
        self.ctx.memory_barrier(moderngl.BUFFER_UPDATE_BARRIER_BIT)
        self.ssbos[slot].read_into(self._packed[slot])

    def _infer(self, slot: int, light_scale: float | None = None, camera=None, light=None) -> tuple[np.ndarray, float]:
        """Run the model on a slot's inputs (on the worker thread when pipelined); its own timer, its wall ms."""
        t0 = time.perf_counter()
        # encoding 3's camera and 4's lights (runtimes of other models take neither)
        if self.lean is not None:
            y = self.model.run_generator(self.lean.encoded[slot], timer=StageTimer())
            return y, (time.perf_counter() - t0) * 1e3
        extra = {k: v for k, v in (("camera", camera), ("light", light)) if v is not None}
        y = self.model.run(self._packed[slot], timer=StageTimer(), light_scale=light_scale, **extra)
        return y, (time.perf_counter() - t0) * 1e3

    def inputs_for(self, scene, config) -> dict:
        """What ``run`` needs for a frame of ``config`` at this pass's GI size: its conditioning
        (`diviewer.contract.conditioning`, `NeuralGI.frame_inputs`); nothing for a runtime without one."""
        inputs = getattr(self.model, "frame_inputs", None)
        return inputs(config, *self.gi_size, scene) if inputs is not None else {}

    def run(self, light_scale: float | None = None, camera=None, light=None, frame: Frame | None = None
            ) -> moderngl.Texture:
        """Infer the GI image from a frame's buffers: ``frame``, else the renderer's last (call after
        renderer.render).

        ``light_scale``, ``camera`` and ``light``: the frame's conditioning (``inputs_for(scene, config)``), for
        models of encoding version 2 to 4. Pipelined, the returned texture holds the previous frame's prediction
        (this frame's, on the first).
        """
        self._frame(frame)  # may run the direct pass: before this pass's stages
        before = {k: self.timer.times.get(k, 0.0) for k in STAGES}
        slot = self._slot
        if self.lean is not None:
            self.lean.set_frame(slot, *self.gi_size, light_scale, camera, light)
        with self.timer.stage("readback"):
            self._pack(slot)
        t_inputs = time.perf_counter()
        if not self.pipelined:
            y, ms = self._infer(slot, light_scale, camera, light)
            self.timer.add("inference", ms)
            self._show(y, slot, t_inputs)
        else:
            if self._worker is None:
                self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="diviewer-gi")
            previous = self._inflight
            self._inflight = (self._worker.submit(self._infer, slot, light_scale, camera, light), slot, t_inputs)
            self._slot = 1 - slot
            if previous is None and self.output is None:
                # The very first frame waits for its own prediction (there is nothing older to show) ...
                previous, self._inflight = self._inflight, None
            if previous is not None:
                future, prev_slot, prev_t = previous
                with self.timer.stage("inference_wait"):
                    y, ms = future.result()
                self.timer.add("inference", ms)
                self._show(y, prev_slot, prev_t)
            # ... and the second shows the first's again while its own runs: from then on one is in flight.
        self.timings = {k: self.timer.times[k] - before[k] for k in STAGES if k in self.timer.times}
        return self.texture

    def _show(self, y: np.ndarray, slot: int, t_inputs: float) -> None:
        with self.timer.stage("upload"):
            if self.lean is not None:
                self.lean.show(y, slot, self.ssbos[slot], self.texture)
            else:
                self.texture.write(y)  # (1, H, W, 3) float32, contiguous: uploaded as is
        self.output, self.shown_slot = y, slot
        self.copies["upload_bytes"] = y.nbytes
        self.latency_ms = (time.perf_counter() - t_inputs) * 1e3

    def image(self) -> np.ndarray:
        """The last output as (H, W, 3) float32 linear radiance, top row first."""
        if self.output is None:
            raise RuntimeError("NeuralPass.run has not been called")
        if self.lean is not None:  # the decoded radiance, read back from the GPU on demand
            w, h = self.gi_size
            return np.frombuffer(self.texture.read(), np.float32).reshape(h, w, 4)[..., :3].copy()
        return self.output[0]

    # --- the full-resolution frame ----------------------------------------------------------------
    def _final_target(self, size: tuple[int, int]) -> moderngl.Framebuffer:
        if self.final is None or self.final.size != size:
            self._release_final()
            self.final = self.ctx.texture(size, 4, dtype="f2")  # half floats: radiance needs no more
            self.final.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._final_fbo = self.ctx.framebuffer([self.final])
        return self._final_fbo

    def composite(self, indirect_only: bool = False) -> moderngl.Texture:
        """The full-resolution frame: the renderer's direct light plus the last output's indirect light,
        upsampled by the joint bilateral filter (``indirect_only``: the upsampled indirect light alone)."""
        if self.output is None:
            raise RuntimeError("NeuralPass.run has not been called")
        frame = self._frame(again=True)  # run()'s frame, or the renderer's if it drew one since
        prog, s = self.upsample, self.settings
        fbo = self._final_target(frame.size)
        w, h = self.gi_size
        with self.timer.stage("upsample", gpu=True):
            self.ssbos[self.shown_slot].bind_to_storage_buffer(0)
            self.texture.use(location=0)
            set_uniform(self.guide, "u_output", 0)
            set_uniform(self.guide, "u_gi_size", self.gi_size)
            for i, t in enumerate(self.guides):
                t.bind_to_image(i, read=False, write=True)
            self.guide.run((w + 7) // 8, (h + 7) // 8, 1)
            self.ctx.memory_barrier(moderngl.TEXTURE_FETCH_BARRIER_BIT)
            fbo.use()
            self.ctx.enable_only(moderngl.NOTHING)
            frame.bind(prog)
            for i, (name, t) in enumerate(zip(("u_irradiance_depth", "u_guide_normal"), self.guides)):
                t.use(location=5 + i)
                set_uniform(prog, name, 5 + i)
            set_uniform(prog, "u_gi_size", self.gi_size)
            set_uniform(prog, "u_depth_sigma", float(s.depth_sigma))
            set_uniform(prog, "u_normal_power", float(s.normal_power))
            set_uniform(prog, "u_indirect_only", bool(indirect_only))
            if prog.glo not in self._vaos:
                self._vaos[prog.glo] = self.ctx.vertex_array(prog, [])
            self._vaos[prog.glo].render(moderngl.TRIANGLES, vertices=3)
        self.timings["upsample"] = self.timer.times.get("upsample", 0.0)
        return self.final

    def _release_final(self) -> None:
        if self.final is not None:
            unbind_framebuffer(self.ctx)
            self._final_fbo.release()
            self.final.release()
            self.final = self._final_fbo = None

    def release(self) -> None:
        if self._worker is not None:
            self._worker.shutdown(wait=True)  # never release what a running inference reads
            self._worker = None
        self._inflight = None
        self._release_final()
        for vao in self._vaos.values():
            vao.release()
        self._vaos.clear()
        if self.lean is not None:
            self.lean.release()
        for b in (*self.ssbos, *self.guides):
            b.release()
        self.texture.release()
