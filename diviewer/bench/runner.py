"""The benchmark's measurements: frame timing per stage on a headless GL context, and each method's accuracy
against the scene's evaluation set (torch-free).

A method is timed as the viewer runs it: the renderer's passes, then its own stages, then the composite
into an 8-bit frame; a warm-up, then one frame per configuration. The path tracer is timed by the wall
clock around Mitsuba's render (scene loading excluded). Accuracy is scored by diviewer.evaluation.evaluate on the
evaluation set's stored buffers, pooled over both of its splits.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from diviewer.errors import DiviewerError
from diviewer.timing import StageTimer

STAGES = ("shadows", "gbuffer", "direct", "readback", "inference", "upload", "upsample", "composite")
"""Every stage a GL frame may have, in frame order; the path tracer's one stage is ``path_trace``; VXGI rows
have diviewer.gl.vxgi.STAGES after ``direct``."""


def stats(values) -> dict[str, float]:
    """median, p95 and max of milliseconds."""
    v = np.asarray(list(values), np.float64)
    return {"median": float(np.median(v)), "p95": float(np.percentile(v, 95)), "max": float(v.max())}


def timing_summary(frames: list[dict[str, float]], totals: list[float]) -> dict:
    """Per stage and per frame: median, p95, max; fps from the median frame; overhead outside inference."""
    stages = {k: stats(f[k] for f in frames if k in f) for k in dict.fromkeys(k for f in frames for k in f)}
    frame = stats(totals)
    inference = stages.get("inference", {}).get("median", 0.0)
    return {"frames": len(totals), "frame": frame, "stages": stages, "fps": 1e3 / frame["median"],
            "overhead_fraction": max(frame["median"] - inference, 0.0) / frame["median"]}


# --- GL timing -----------------------------------------------------------------------------------------------------

def gl_timing_mode(ctx, requested: str = "auto") -> str:
    """``query`` (GL timer queries: GL_ARB_timer_query or GL >= 3.3) or ``sync`` (wall clock around glFinish)."""
    if requested in ("query", "sync"):
        return requested
    return "query" if ("GL_ARB_timer_query" in ctx.extensions or ctx.version_code >= 330) else "sync"


@dataclass
class GlBench:
    """One resolution's renderer, display pass and target, and the stage timer every pass reports to."""

    ctx: object
    scene: object
    width: int
    height: int
    mode: str
    window: tuple[int, int] | None = None
    """The target's size (the viewer's window) where the frame is shaded at another (a render scale): the display
    pass magnifies (or averages) it bilinearly, as the viewer does; None: the shading size."""
    moving_shadow_size: int | None = None
    """A moving sun's map size in the timed frames; None: `MOVING_SHADOW_SIZE`."""
    renderer: object = field(init=False)
    timer: StageTimer = field(init=False)

    def __post_init__(self):
        import moderngl

        from diviewer.gl.context import stage_timer
        from diviewer.gl.display import DisplayPass
        from diviewer.gl.renderer import Renderer

        self.timer = stage_timer(self.ctx, sync=self.mode == "sync", queries=self.mode == "query")
        self.renderer = Renderer(self.ctx, self.scene, self.width, self.height, timer=self.timer)
        self.display = DisplayPass(self.ctx, self.renderer.shaders)
        size = tuple(self.window or (self.width, self.height))
        self.target_tex = self.ctx.texture(size, 4)
        self.target = self.ctx.framebuffer([self.target_tex])
        self.upscale = None if size == (self.width, self.height) else self.ctx.sampler(
            filter=(moderngl.LINEAR, moderngl.LINEAR), repeat_x=False, repeat_y=False)

    def present(self, tex, flip_y: bool = False, exposure: float = 0.0, tonemap: str | None = None) -> None:
        """The display pass from ``tex`` to the target: tone-mapped 8-bit, bilinear where the sizes differ (the
        viewer's upscale sampler over the display's texture unit)."""
        from diviewer.gl.display import DEFAULT_TONEMAP

        if self.upscale is not None:
            self.upscale.use(location=0)
        self.display.run(tex, self.target, exposure, tonemap or DEFAULT_TONEMAP, flip_y=flip_y)
        if self.upscale is not None:
            self.upscale.clear(location=0)

    def run(self, configs, warmup: int, method, direct: bool = True) -> dict:
        """Time ``method(config) -> (texture, flip_y)`` (called after the renderer's passes) over ``configs``;
        ``direct=False`` defers the direct pass as the viewer does (Renderer.render). The sun moves every frame, so
        its shadow map is drawn at the viewer's size for a moving sun (`MOVING_SHADOW_SIZE`), as the viewer draws
        it; every image scored for accuracy is drawn with the full map."""
        from diviewer.gl.shadow_fit import MOVING_SHADOW_SIZE

        self.renderer.moving_shadow_size = self.moving_shadow_size or MOVING_SHADOW_SIZE
        try:
            return self._run(configs, warmup, method, direct)
        finally:
            self.renderer.moving_shadow_size = None

    def _run(self, configs, warmup: int, method, direct: bool) -> dict:
        frames, totals = [], []
        for i, config in enumerate([configs[k % len(configs)] for k in range(warmup)] + list(configs)):
            self.timer.reset()
            t0 = time.perf_counter()
            self.renderer.render(config, direct=direct)
            tex, flip = method(config)
            with self.timer.stage("composite", gpu=True):
                self.present(tex, flip_y=flip)
            self.ctx.finish()
            ms = (time.perf_counter() - t0) * 1e3
            if i >= warmup:
                frames.append(dict(self.timer.times))
                totals.append(ms)
        self.per_frame = [{"frame": ms, **f} for f, ms in zip(frames, totals)]  # the last run's, frame by frame
        return timing_summary(frames, totals)

    def time_direct(self, configs, warmup: int) -> dict:
        return self.run(configs, warmup, lambda c: (self.renderer.textures["direct"], False))

    def time_model(self, net, configs, warmup: int, step: int = 1, lean: bool = True,
                   gi_size: tuple[int, int] | None = None) -> dict:
        """The viewer's neural frame: pack at the GI resolution (frame / step), infer, upload, the joint
        bilateral upsample over the frame's direct light (diviewer.gl.neural), composite; the direct light
        computed inline as the viewer does where the frame allows (NeuralPass.inline_direct); on the model's
        lean path where it has one and ``lean`` (GISettings.lean); ``gi_size`` replaces frame / step."""
        neural = self.neural_pass(net, step, lean, gi_size)
        try:
            def frame(config):
                neural.run(**neural.inputs_for(self.scene, config))
                return neural.composite(), False

            return self.run(configs, warmup, frame, direct=False)
        finally:
            neural.release()

    def time_vxgi(self, vxgi_settings, configs, warmup: int) -> dict:
        """The viewer's VXGI frame: the pass's stages (diviewer.gl.vxgi) on the shared timer, then the composite.

        Each configuration differs from the last in light and object, so a frame re-voxelizes the moving
        objects and re-injects the light; the static geometry is voxelized once, in the warm-up. Per-stage
        figures are over the frames where the stage ran.
        """
        from diviewer.gl.vxgi import VXGIPass

        vx = VXGIPass(self.ctx, self.renderer, vxgi_settings, timer=self.timer)
        try:
            return self.run(configs, warmup, lambda c: (vx.run(c)["vxgi"], False))
        finally:
            vx.release()

    def vxgi_frames(self, vxgi_settings, configs) -> list[np.ndarray]:
        """VXGI's composited image (direct + albedo x indirect) of each configuration, (H, W, 3) float32."""
        from diviewer.gl.vxgi import VXGIPass

        vx = VXGIPass(self.ctx, self.renderer, vxgi_settings, timer=self.timer)
        try:
            out = []
            for config in configs:
                self.renderer.render(config)
                vx.run(config)
                out.append(vx.read("vxgi"))
            return out
        finally:
            vx.release()
            self.timer.reset()

    def neural_pass(self, net, step: int = 1, lean: bool = True, gi_size: tuple[int, int] | None = None):
        from diviewer.gl.neural import GISettings, NeuralPass

        return NeuralPass(self.ctx, self.renderer, net, gi_size=gi_size or (self.width // step, self.height // step),
                          settings=GISettings(lean=lean))

    def buffers(self, config) -> np.ndarray:
        """The model input of one configuration at this resolution, (1, H, W, 10) (for calibration)."""
        from diviewer.contract.runtime import pack_buffers

        return pack_buffers(self.renderer.frame(config))[None]

    def release(self) -> None:
        from diviewer.gl.context import unbind_framebuffer

        self.timer.reset()
        unbind_framebuffer(self.ctx)
        self.target.release()
        self.target_tex.release()
        if self.upscale is not None:
            self.upscale.release()
        self.display.release()
        self.renderer.release()
        self.timer.release()


# --- the path tracer -----------------------------------------------------------------------------------------------

def time_path_tracer(scene, configs, width: int, height: int, ladder: list[int], max_depth: int = 16) -> dict:
    """Wall-clock milliseconds per frame of Mitsuba at each sample count, by the estimator the evaluation sets' truth
    and ladder are rendered with (`MitsubaFrame.full_light`: one pass where the frame allows); one untimed
    warm-up render per count (the first render of a kernel compiles it)."""
    from diviewer.reference.mitsuba import MitsubaFrame

    loaded = [MitsubaFrame(scene, c, width, height) for c in configs]
    out = {}
    for spp in ladder:
        loaded[0].full_light(spp, 0, max_depth)
        totals = []
        for k, frame in enumerate(loaded):
            t0 = time.perf_counter()
            frame.full_light(spp, k + 1, max_depth)
            totals.append((time.perf_counter() - t0) * 1e3)
        out[spp] = timing_summary([{"path_trace": t} for t in totals], totals)
    return out


# --- accuracy ------------------------------------------------------------------------------------------------------

def read_final(tex) -> np.ndarray:
    """A NeuralPass's composited frame (half floats, rows bottom first) as (H, W, 3) float32, top row first."""
    w, h = tex.size
    raw = np.frombuffer(tex.read(), np.float16).reshape(h, w, 4)[..., :3]
    return np.ascontiguousarray(np.flipud(raw), dtype=np.float32)


def per_split(ds, idx: list[int], frames_per_split: int | None) -> list[int]:
    """The first ``frames_per_split`` of ``idx`` in each of the evaluation set's splits (None: all of them)."""
    if frames_per_split is None:
        return list(idx)
    by_split: dict[str, list[int]] = {}
    for i in idx:
        by_split.setdefault(ds.entry(i)["split"], []).append(i)
    return [i for s in by_split.values() for i in s[:frames_per_split]]


def score_evalset(ds, idx: list[int], shape: tuple[int, int], models: dict, frames_per_split: int | None,
                  gl: GlBench | None = None, log=print, vxgi: dict | None = None) -> dict:
    """Every method's pooled metrics over the evaluation set's frames ``idx`` cropped to ``shape``
    (diviewer.evaluation.frames.EvalFrames.bench_frames: the scene-camera splits at the model's square).

    A model at its full resolution (step 1) is scored on its output for the stored buffers, as `diviewer eval`
    does; below it (step > 1) on the frame the viewer shows: the configuration rendered again by ``gl`` (at
    ``shape``: the same buffers), packed at the GI resolution, upsampled and composited. VXGI is scored on its
    composited frame of the configuration rendered again by ``gl``. The path tracer's ladder comes from its
    stored frames, or from a compact set's stored scores.

    Args:
        models: key -> (NeuralGI, step).
        vxgi: key -> VXGISettings (needs ``gl``).
    Returns:
        ``{"frames", "ladder_spp", "methods": {key: aggregate}}`` with ``direct``, ``noise_floor`` and
        ``pt_spp<n>`` beside the models; each aggregate carries its ``equivalent_spp``.
    """
    from diviewer.evaluation.frames import crop_frame, split_key
    from diviewer.evaluation.scoring import aggregate, equivalent, ladder_methods, score_frame
    from diviewer.evaluation.evaluate import area_direct_of, model_input, run_model
    from diviewer.metrics import flat_mask
    from diviewer.scene.loader import config_from_dict

    info = ds.manifest["evalset"]
    exposure = ds.exposure
    ladder_spp = [int(n) for n in info["ladder_spp"]]
    channels = {"direct": "direct", "noise_floor": info["second_seed_channel"],
                **(ladder_methods(ds) if ds.ladder_images() else {})}
    idx = per_split(ds, idx, frames_per_split)
    splits = ds.splits()
    vxgi = vxgi or {}
    rows = {k: [] for k in (*models, *vxgi, *channels, *([] if ds.ladder_images() else ladder_methods(ds)))}
    configs = [config_from_dict(gl.scene, ds.entry(i)["config"]) for i in idx] if vxgi else []
    vx_images = {key: gl.vxgi_frames(s, configs) for key, s in vxgi.items()}
    passes = {key: gl.neural_pass(net, step) for key, (net, step) in models.items() if step > 1}
    # models of the direct light over each pixel's area take it (as diviewer eval feeds them) at the set's size
    area = area_direct_of(ds, {net.direct_samples for net, step in models.values() if step == 1} - {1},
                          ctx=gl.ctx if gl is not None else None)
    try:
        for n, i in enumerate(idx):
            frame = ds.load(i)
            f = crop_frame(frame, shape[0])
            mask = flat_mask(f["depth"], f["normal"], f["albedo"], f["direct"])  # as diviewer eval
            config = config_from_dict(gl.scene, ds.entry(i)["config"]) if models else None  # models need a GL scene
            if passes:
                gl.renderer.render(config, direct=False)  # as timed
            for key, (net, step) in models.items():
                if step == 1:  # the model at the set's size, with the frame's conditioning
                    x = model_input(net, f, frame, area, i, shape[0])
                    image = run_model(net, x, **net.frame_inputs(config, shape[0], shape[1], gl.scene))
                else:
                    passes[key].run(**passes[key].inputs_for(gl.scene, config))
                    image = read_final(passes[key].composite())
                rows[key].append(score_frame(image, f["pt"], exposure, mask))
            for key, images in vx_images.items():
                rows[key].append(score_frame(images[n], f["pt"], exposure, mask))
            for key, ch in channels.items():
                rows[key].append(score_frame(f[ch], f["pt"], exposure, mask))
            if not ds.ladder_images():
                split = ds.entry(i)["split"]
                for key, row in ds.ladder_rows(i, split_key(split, list(shape), splits[split])).items():
                    rows[key].append(row)
    finally:
        for p in passes.values():
            p.release()
    methods = {k: aggregate(r) for k, r in rows.items() if r}
    ladder = [methods[f"pt_spp{n}"] for n in ladder_spp]
    for m in methods.values():
        m["equivalent_spp"] = equivalent(m, ladder_spp, ladder)
    return {"frames": len(idx), "ladder_spp": ladder_spp, "exposure": exposure, "methods": methods}


# --- temporal stability --------------------------------------------------------------------------------------------

def temporal_configs(scene, n: int, span: float = 0.25) -> list:
    """A smooth sequence from the default configuration: each ranged light turned through ``span`` of its
    range and, when the scene has a camera path, the camera moved along ``span`` of it."""
    import dataclasses

    from diviewer.scene.lights import rotate_light
    from diviewer.scene.sampler import camera_on_path

    base = scene.default
    centre = scene.bounds().mean(axis=0)
    out = []
    for i in range(n):
        t = span * i / max(n - 1, 1)
        lights = []
        for light in base.lights:
            r = scene.ranges.lights.get(light.name)
            lights.append(light if r is None else rotate_light(light, r.axis, r.angle[0] + t * (r.angle[1] - r.angle[0]),
                                                               centre))
        camera = base.camera if scene.ranges.camera is None else camera_on_path(scene, t)
        out.append(dataclasses.replace(base, lights=tuple(lights), camera=camera))
    return out


def calibration(settings, scene, ctx, width: int, height: int, mode: str, encoding) -> tuple[list[tuple], str]:
    """Model inputs of training frames, each (buffers (1, H, W, 10), its conditioning under ``encoding``, a model's
    (`diviewer.contract.conditioning`)). A capture's train split when given, else GL renders (in ``ctx``, timed by
    ``mode`` as GlBench times) of training configs."""
    from diviewer.contract.conditioning import conditioning

    size = (width, height)
    if settings.calib_data:
        from diviewer.data.dataset import Dataset
        from diviewer.contract.runtime import pack_buffers

        ds = Dataset(settings.calib_data)
        idx = ds.indices("train")[: settings.calib_frames]
        if not idx:
            raise DiviewerError("no train frames to calibrate int8 on", path=settings.calib_data)
        frames = [pack_buffers(ds.load(i)) for i in idx]
        if frames[0].shape[:2] == (height, width):
            configs = {f["index"]: f.get("config") for f in ds.frames}
            manifest = ds.root / "manifest.json"
            return ([(f[None], conditioning(scene, configs[i], size, encoding, path=manifest))
                     for i, f in zip(idx, frames)], f"{len(idx)} train frames of {settings.calib_data}")
    from diviewer.scene import sample_config

    configs = [sample_config(scene, 9000 + i, "train") for i in range(settings.calib_frames)]
    gb = GlBench(ctx, scene, width, height, mode)
    try:
        inputs = [(gb.buffers(c), conditioning(scene, c, size, encoding)) for c in configs]
    finally:
        gb.release()
    return inputs, f"GL inputs of {settings.calib_frames} training configurations"


def temporal_rows(ctx, settings, scene, ds, variants, net_of, mode, notes, log, seq=None) -> dict | None:
    """Frame-to-frame change of each method along a smooth sequence (``seq``, default `temporal_configs`) against
    the path tracer's (Mitsuba needed)."""
    from diviewer.bench.frontier import temporal_stability
    from diviewer.contract.encoding import fit_exposure
    from diviewer.metrics import tonemap
    from diviewer.contract.runtime import pack_buffers

    try:
        from diviewer.reference.mitsuba import MitsubaFrame, import_mitsuba as _import_mitsuba

        _import_mitsuba()
    except DiviewerError as exc:
        notes.append(f"no temporal stability: {exc}")
        return None
    res = ds.bench_frames()[1][0] if ds is not None else settings.resolutions[0]
    seq = temporal_configs(scene, settings.temporal_frames) if seq is None else seq
    log(f"temporal stability: {len(seq)} frames at {res}x{res}, reference {settings.temporal_spp} spp")
    gb = GlBench(ctx, scene, res, res, mode)
    try:
        buffers = [gb.renderer.frame(c) for c in seq]
        vx = {f"vxgi{g}": gb.vxgi_frames(settings.vxgi(g), seq) for g in settings.vxgi_grids}
    finally:
        gb.release()
    exposure = float(ds.manifest["evalset"]["tonemap"]["exposure"]) if ds is not None else \
        fit_exposure([b["direct"] for b in buffers])
    frames = [MitsubaFrame(scene, c, res, res) for c in seq]
    ref = [f.full_light(settings.temporal_spp, 0) for f in frames]  # one seed: the reference's noise holds still
    seqs = {"direct": [b["direct"] for b in buffers], **vx}
    for v in variants:  # any size runs: the runtime pads to the model's stride (and guard) and crops back
        net = net_of(v)
        seqs[f"{v['path']}|1"] = [net.run(pack_buffers(b), **net.frame_inputs(c, res, res, scene))
                                  for b, c in zip(buffers, seq)]
    ladder = [int(n) for n in ds.manifest["evalset"]["ladder_spp"]] if ds is not None else list(settings.pt_spp)
    ladder = [n for n in ladder if settings.temporal_max_spp is None or n <= settings.temporal_max_spp]
    for n in ladder:  # a real-time path tracer draws new samples every frame
        seqs[f"pt_spp{n}"] = [f.full_light(n, 1 + k) for k, f in enumerate(frames)]
    ref_tm = [tonemap(x, exposure) for x in ref]
    out = {k: temporal_stability([tonemap(x, exposure) for x in s], ref_tm) for k, s in seqs.items()}
    return {"resolution": [res, res], "frames": len(seq), "reference_spp": settings.temporal_spp,
            "tonemap_exposure": exposure, "methods": out,
            "measure": "mean |frame t+1 - frame t| of tone-mapped images; ratio = method / reference; excess = "
                       "mean |delta method - delta reference|"}
