"""The per-frame neural GI model in onnxruntime: load, check its metadata against the scene, run.

The model contract (written by ``diviewer export``, read here; torch-free):

- input ``buffers``: float32, linear and raw, channels in ``diviewer.contract.encoding.INPUT_CHANNELS`` order
  (depth, normal xyz, albedo rgb, direct rgb), rows top first; (N, H, W, 10) when the metadata's
  ``layout`` is "NHWC" (every model before the lean graph), (N, 10, H, W) when it is "NCHW" (no
  transpose before the first convolution); H and W multiples of the model's ``multiple``: ``run``
  pads any other size to it (`diviewer.contract.padding`, as training pads) and crops the output back; a model trained on
  random-width crops gets at least `diviewer.contract.padding.EDGE_GUARD` columns of padding a side (``edge_guard``);
- for encoding version 2 a second input ``light_scale``: float32 (N,), each frame's light scale
  (`diviewer.scene.lights.light_scale`): the graph divides the direct light by it and multiplies its
  output by it, so the model is linear in the light (0 gives exactly 0);
- for encoding version 3 a third input ``camera`` (N, CAMERA_PARAMS), each frame's camera; for version 4 a fourth,
  ``light`` (N, 3 L), where each of the scene's L lights is (`diviewer.scene.lights.light_params`);
- one output ``radiance``: float32 (N, H, W, 3) linear radiance of the final image (for a model of
  the ``indirect`` target the exact direct light is already added inside the graph);
- the encoding and decoding live inside the graph; the metadata key ``diviewer`` holds a JSON
  object describing the model (see REQUIRED_META);
- the weights may be stored as float16 in a float32 graph (metadata ``weights`` "fp16", ``export
  --half-weights``): each behind a Cast to float32 that onnxruntime folds at load (`diviewer.contract.weights`); or the
  inner convolutions' as int8 (``weights`` "int8", ``export --int8-weights``): each behind a Cast and a Mul by
  its per-channel scales, folded alike.
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np

from diviewer.contract.encoding import ENCODING_VERSION, INPUT_CHANNELS, OUTPUT_CHANNELS
from diviewer.errors import DiviewerError
from diviewer.contract.padding import crop_nhwc, edge_guard, pad_camera_params, pad_nhwc
from diviewer.scene.camera import CAMERA_PARAMS
from diviewer.scene.lights import LIGHT_PARAMS
from diviewer.timing import StageTimer

INPUT_NAME = "buffers"
LIGHT_SCALE_NAME = "light_scale"
CAMERA_NAME = "camera"
"""Encoding version 3's third input: each frame's camera, (N, CAMERA_PARAMS) (`diviewer.scene.camera.camera_params`)."""
LIGHT_NAME = "light"
"""Encoding version 4's fourth input: where each light of the frame is, (N, 3 L) (`diviewer.scene.lights.light_params`)."""
LAYOUTS = ("NHWC", "NCHW")
"""Input layouts a model may take (its metadata's ``layout``); the output is NHWC radiance either way."""
OUTPUT_NAME = "radiance"
META_KEY = "diviewer"
MODEL_FORMAT = 1
REQUIRED_META = ("format", "input", "output", "layout", "channels", "resolution", "multiple", "K", "levels",
                 "target", "encoding", "precision", "scene", "scene_hash", "dataset_hash")
PROVIDER_ORDER = ("TensorrtExecutionProvider", "CUDAExecutionProvider", "CPUExecutionProvider")


def read_metadata(path: str | Path) -> dict:
    """The model's diviewer metadata (without running it); refuses files that lack it."""
    import onnxruntime as ort

    path = Path(path)
    if not path.is_file():
        raise DiviewerError(f"model file not found: {path}")
    try:
        session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    except Exception as exc:
        raise DiviewerError(f"cannot load the ONNX model (truncated or not ONNX?): {exc}", path=path) from exc
    return _metadata(session, path)


def _metadata(session, path: Path) -> dict:
    props = session.get_modelmeta().custom_metadata_map
    if META_KEY not in props:
        raise DiviewerError("the model has no diviewer metadata (was it made by `diviewer export`?)", path=path,
                            field=META_KEY)
    try:
        meta = json.loads(props[META_KEY])
    except json.JSONDecodeError as exc:
        raise DiviewerError(f"the model's metadata is not valid JSON: {exc}", path=path, field=META_KEY) from exc
    if not isinstance(meta, dict):
        raise DiviewerError("the model's metadata is not a JSON object", path=path, field=META_KEY)
    missing = [k for k in REQUIRED_META if k not in meta]
    if missing:
        raise DiviewerError(f"the model's metadata lacks {', '.join(missing)}", path=path, field=META_KEY)
    _check_meta_types(meta, path)
    return meta


def _is_int(v, lo: int = 0) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and v >= lo


def _check_meta_types(meta: dict, path: Path) -> None:
    """Refuse metadata of the wrong types (a hand-edited or foreign model) before anything divides by it."""
    checks = {
        "format": _is_int(meta["format"]),
        "input": isinstance(meta["input"], str), "output": isinstance(meta["output"], str),
        "layout": isinstance(meta["layout"], str),
        "channels": isinstance(meta["channels"], list) and all(isinstance(c, (list, tuple)) for c in meta["channels"]),
        "resolution": isinstance(meta["resolution"], list) and len(meta["resolution"]) == 2
        and all(_is_int(x, 1) for x in meta["resolution"]),
        # sizes are checked modulo this: zero would divide by zero, and the U-Net halves it per level
        "multiple": _is_int(meta["multiple"], 1) and meta["multiple"] & (meta["multiple"] - 1) == 0,
        "K": _is_int(meta["K"]), "levels": _is_int(meta["levels"]),  # 0: a baseline without a network
        "target": meta["target"] in ("full", "indirect", "residual"),
        "encoding": isinstance(meta["encoding"], dict) and _is_int(meta["encoding"].get("version", 0)),
        # int8 only as bench's static quantisation writes it: with the record of how it was quantised
        "precision": meta["precision"] in ("fp32", "fp16")
        or (meta["precision"] == "int8" and isinstance(meta.get("quantization"), dict)),
        "scene": isinstance(meta["scene"], str), "scene_hash": isinstance(meta["scene_hash"], str),
        "dataset_hash": isinstance(meta["dataset_hash"], str),
        # optional (cards before it hold the pixel centre's light): samples per axis of the direct light it takes
        "direct_samples": _is_int(meta.get("direct_samples", 1), 1) and meta.get("direct_samples", 1) <= 8,
    }
    bad = [k for k, ok in checks.items() if not ok]
    if bad:
        raise DiviewerError(f"the model's metadata has a wrong value for {bad[0]}: {meta[bad[0]]!r}", path=path,
                            field=f"{META_KEY}.{bad[0]}")


def check_compatible(meta: dict, path: Path, scene=None) -> None:
    """Refuse a model that does not fit this diviewer, these buffers or this scene, saying why."""
    if int(meta["format"]) > MODEL_FORMAT:
        raise DiviewerError(f"model format {meta['format']} is newer than this diviewer reads ({MODEL_FORMAT})",
                            path=path, field="format")
    enc_version = int(meta["encoding"].get("version", 0))
    if enc_version > ENCODING_VERSION:
        raise DiviewerError(f"the model uses encoding version {enc_version}, newer than this diviewer's "
                            f"({ENCODING_VERSION}); upgrade diviewer", path=path, field="encoding.version")
    if enc_version >= 3:  # the world box (3) and the light count (4) that the graph's extra inputs are made with
        from diviewer.contract.encoding import Encoding

        try:
            Encoding.from_dict(meta["encoding"])
        except DiviewerError as exc:
            raise DiviewerError(f"the model's metadata holds a broken encoding ({exc})", path=path,
                                field=f"{META_KEY}.encoding") from None
    expected = [list(c) for c in INPUT_CHANNELS]
    if [list(c) for c in meta["channels"]] != expected:
        raise DiviewerError(f"the model expects input channels {meta['channels']}, the renderer provides {expected}",
                            path=path, field="channels")
    if meta["layout"] not in LAYOUTS or meta["input"] != INPUT_NAME or meta["output"] != OUTPUT_NAME:
        raise DiviewerError(f"the model's inputs/outputs ({meta['input']} -> {meta['output']}, {meta['layout']}) "
                            f"are not diviewer's ({INPUT_NAME} -> {OUTPUT_NAME}, {' or '.join(LAYOUTS)})", path=path,
                            field="layout")
    if scene is not None and meta["scene_hash"] != scene.file_hash:
        same_name = meta["scene"] == scene.name
        raise DiviewerError(
            f"the model was trained for scene '{meta['scene']}'"
            + (" as it was in another version of its file" if same_name else "")
            + f", not for '{scene.name}' (scene file hash {meta['scene_hash'][:12]}... != {scene.file_hash[:12]}...)",
            path=path, field="scene_hash")


PROVIDER_ALIASES = {"cpu": "CPUExecutionProvider", "cuda": "CUDAExecutionProvider",
                    "tensorrt": "TensorrtExecutionProvider"}


def choose_providers(available: list[str], requested: str | None = None) -> list[str]:
    """The best available execution providers (TensorRT, CUDA, CPU), or the one requested first."""
    if not requested:
        return [p for p in PROVIDER_ORDER if p in available] or list(available)
    name = PROVIDER_ALIASES.get(requested.lower(), requested)
    if name not in available:
        raise DiviewerError(f"execution provider '{requested}' is not available; available: {', '.join(available)}",
                            field="--provider")
    return [name] + (["CPUExecutionProvider"] if name != "CPUExecutionProvider" else [])


def model_edge_guard(meta: dict) -> int:
    """The column guard a model runs with (`diviewer.contract.padding.edge_guard`): from the aspect crops its recipe trained
    with (the model's ``recipe`` record; none recorded: whole frames, no guard)."""
    train = (meta.get("recipe") or {}).get("train") or {}
    return edge_guard(train.get("aspect_crops"))


class NeuralGI:
    """One loaded model: checks, then turns (N, H, W, 10) raw buffers into (N, H, W, 3) radiance."""

    def __init__(self, path: str | Path, scene=None, provider: str | None = None, threads: int = 0,
                 spin: bool = False, guard: int | None = None):
        import onnxruntime as ort

        self.path = Path(path)
        self.scene = scene
        if not self.path.is_file():
            raise DiviewerError(f"model file not found: {self.path}")
        opts = ort.SessionOptions()
        opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        if threads:
            opts.intra_op_num_threads = threads
        # Unless ``spin``, onnxruntime's worker threads sleep after a run instead of spinning for the next:
        # in the viewer and the benchmark the next work is the frame's GL passes, which a software
        # rasterizer runs on the very cores they would spin on (tools/experiments/frame_probe.py --compare spin).
        if not spin:
            opts.add_session_config_entry("session.intra_op.allow_spinning", "0")
        providers = choose_providers(ort.get_available_providers(), provider)
        self.session_options = opts
        """The session's options (`diviewer.contract.lean` builds the generator's session with them)."""
        try:
            self.session = ort.InferenceSession(str(self.path), sess_options=opts, providers=providers)
        except Exception as exc:
            raise DiviewerError(f"cannot load the ONNX model (truncated or not ONNX?): {exc}", path=self.path) from exc
        self.meta = _metadata(self.session, self.path)
        check_compatible(self.meta, self.path, scene)
        inputs, outputs = self.session.get_inputs(), self.session.get_outputs()
        from diviewer.contract.encoding import Encoding

        self.encoding = Encoding.from_dict(self.meta["encoding"])
        """The model's encoding (its metadata's); `conditioning` reads what a frame must bring from it."""
        self.light_scaled = self.encoding.light_scaled
        """Encoding version 2: ``run`` needs each frame's light scale."""
        self.world = self.encoding.world_inputs
        """Encoding version 3: ``run`` also needs each frame's camera (`camera`)."""
        self.lit = self.encoding.light_inputs
        """Encoding version 4: ``run`` also needs each frame's lights (`lights`)."""
        self.light_count = self.encoding.lights if self.lit else 0
        """Encoding version 4: how many lights the ``light`` input describes (three numbers each)."""
        self.direct_samples = int(self.meta.get("direct_samples", 1))
        """Samples per axis of the direct light the model was trained on (`diviewer.gl.area`): 1 is the light at
        each pixel's centre; above 1, callers feed the light over the pixel's area (``buffers``' direct channel)."""
        wanted = [INPUT_NAME] + ([LIGHT_SCALE_NAME] if self.light_scaled else []) + \
            ([CAMERA_NAME] if self.world else []) + ([LIGHT_NAME] if self.lit else [])
        if [i.name for i in inputs] != wanted or OUTPUT_NAME not in [o.name for o in outputs]:
            raise DiviewerError(f"the graph's inputs {[i.name for i in inputs]} / outputs {[o.name for o in outputs]} "
                                f"are not diviewer's for encoding version {self.meta['encoding'].get('version')} "
                                f"({wanted} -> {OUTPUT_NAME})", path=self.path)
        self.layout = self.meta["layout"]
        """The input layout the graph takes: "NHWC" or "NCHW" (``run`` takes NHWC and transposes if needed)."""
        channels = inputs[0].shape[1 if self.layout == "NCHW" else -1]
        if channels != sum(n for _, n in INPUT_CHANNELS):
            raise DiviewerError(f"the graph takes {channels} input channels, the renderer provides "
                                f"{sum(n for _, n in INPUT_CHANNELS)}", path=self.path, field="input")
        self.provider = self.session.get_providers()[0]
        self.multiple = int(self.meta["multiple"])
        self.edge_guard = model_edge_guard(self.meta) if guard is None else int(guard)
        """Columns of padding a side at least (`diviewer.contract.padding`): the model's (`model_edge_guard`) unless
        ``guard`` is given."""
        if self.edge_guard < 0:
            raise DiviewerError(f"an edge guard is a number of columns >= 0, got {self.edge_guard}", field="guard")
        self.resolution = tuple(int(x) for x in self.meta["resolution"])
        self.timer = StageTimer()
        """Times ``inference`` (the session's run alone) unless ``run`` is given the caller's timer."""
        self.nonfinite_inputs = 0
        """Input values of the last frame that were NaN or infinite (the graph's encoding maps them to 0)."""
        self.nonfinite_outputs = 0
        """Output values of the last frame that were NaN or infinite (left in place: the display flags them)."""
        probe(self)
        self.timer = StageTimer()  # the probe's run is not a frame
        self.nonfinite_inputs = self.nonfinite_outputs = 0

    @property
    def file_sha256(self) -> str:
        return hashlib.sha256(self.path.read_bytes()).hexdigest()

    def check_size(self, width: int, height: int) -> None:
        """Any size of at least one pixel runs: ``run`` pads it to the model's multiple and crops back."""
        if not (isinstance(width, (int, np.integer)) and isinstance(height, (int, np.integer))
                and width >= 1 and height >= 1):
            raise DiviewerError(f"the model needs a frame of at least 1x1 pixels, got {width}x{height}", path=self.path)

    @property
    def trained_aspects(self) -> tuple[float, float]:
        """The frame shapes it was trained on, as width / height: its recipe's aspect crops (crops of every width
        in the range at full height), else its training resolution's one shape; every shape for a per-pixel model
        (the linear baseline: no pixel sees another, so the frame's shape changes nothing)."""
        if self.meta.get("kind") == "linear_baseline":
            return 0.0, math.inf
        crops = ((self.meta.get("recipe") or {}).get("train") or {}).get("aspect_crops")
        if crops:
            return float(crops[0]), float(crops[1])
        w, h = self.resolution
        return w / h, w / h

    def shape_note(self, width: int, height: int) -> str:
        """Why a ``width`` x ``height`` frame is outside what it was trained on (empty: it is not). Every shape
        runs; one it never saw is extrapolated, and whoever shows the frame says so."""
        lo, hi = self.trained_aspects
        slack = 1.0 / height  # a shape rounded to whole pixels
        if lo - slack <= width / height <= hi + slack:
            return ""
        seen = f"{lo:.3g}" if lo == hi else f"{lo:.3g} to {hi:.3g}"
        return (f"the model was trained on frames of width/height {seen} only; at {width}x{height} "
                f"({width / height:.3g}) its GI is extrapolated and may be wrong")

    def light_scale(self, config, scene=None) -> float:
        """The light scale of a frame (`diviewer.scene.lights.light_scale`) of ``scene`` (default: the
        scene the model was loaded for), to pass to ``run``."""
        from diviewer.scene.lights import light_scale

        scene = scene if scene is not None else self.scene
        if scene is None:
            raise ValueError("light_scale needs the scene: load the model with scene= or pass it")
        return light_scale(scene, config)

    def conditioning(self, config, width: int, height: int, scene=None):
        """The conditioning of a ``width`` x ``height`` frame of ``config`` (`diviewer.contract.conditioning`) of ``scene``
        (default: the scene the model was loaded for) under the model's encoding."""
        from diviewer.contract.conditioning import conditioning

        return conditioning(scene if scene is not None else self.scene, config, (width, height), self.encoding)

    def frame_inputs(self, config, width: int, height: int, scene=None) -> dict:
        """What ``run`` needs besides the buffers for a ``width`` x ``height`` frame of ``config`` (a FrameConfig), as
        keyword arguments: its conditioning's (`conditioning`)."""
        return self.conditioning(config, width, height, scene).inputs()

    def lights(self, config) -> np.ndarray:
        """The ``light`` input of a frame of ``config`` (encoding 4; a FrameConfig, or the dict a dataset stores):
        where each of its lights is, in the world box the model was trained in (`diviewer.contract.conditioning.frame_lights`)."""
        from diviewer.contract.conditioning import frame_lights

        return frame_lights(config["lights"] if isinstance(config, dict) else config.lights, self.encoding)

    @staticmethod
    def camera(camera, width: int, height: int) -> np.ndarray:
        """The ``camera`` input of a ``width`` x ``height`` frame seen by a scene camera (position, target, up, fov:
        `diviewer.scene.Camera` or its dict), for ``run`` (`diviewer.contract.conditioning.frame_camera`)."""
        from diviewer.contract.conditioning import frame_camera

        return frame_camera(camera, (width, height))

    def run(self, buffers: np.ndarray, timer: StageTimer | None = None, light_scale=None,
            camera=None, light=None) -> np.ndarray:
        """(N, H, W, 10) or (H, W, 10) float32 raw buffers to radiance of the same leading shape.

        Any H x W: frames that are not multiples of the model's stride are edge-padded to it and the
        output cropped back (`diviewer.contract.padding`, exactly as training pads), with ``edge_guard`` columns a side at
        least. ``light_scale``: each frame's
        light scale, a number or (N,) (`light_scale`); needed by encoding-2 models, ignored by older ones.
        ``camera``: each frame's camera over its own H x W pixels, (CAMERA_PARAMS,) or (N, CAMERA_PARAMS)
        (`camera`); needed by encoding-3 models, ignored by older ones. ``light``: each frame's lights, (3 L,) or
        (N, 3 L) (`lights`); needed by encoding-4 models, ignored by older ones.
        """
        single = buffers.ndim == 3
        x = buffers[None] if single else buffers
        if x.dtype != np.float32 or not x.flags.c_contiguous:
            x = np.ascontiguousarray(x, dtype=np.float32)
        n, height, width = x.shape[:3]
        self.check_size(width, height)
        # Counted, not replaced: the exported graph's encoding maps non-finite network inputs to 0, and
        # what the graph returns non-finite (a NaN in the direct light it adds) stays visible where it
        # arose (the display flags it) instead of being hidden; the counts say how many.
        self.nonfinite_inputs = count_nonfinite(x)
        feed = pad_nhwc(x, self.multiple, self.edge_guard)
        if self.layout == "NCHW":
            feed = np.ascontiguousarray(feed.transpose(0, 3, 1, 2))
        feeds = {INPUT_NAME: feed}
        if self.light_scaled:
            if light_scale is None:
                raise ValueError(f"{self.path.name} uses encoding version 2: run() needs each frame's light scale "
                                 "(its conditioning: NeuralGI.frame_inputs)")
            s = np.asarray(light_scale, np.float32).reshape(-1)
            feeds[LIGHT_SCALE_NAME] = np.ascontiguousarray(np.broadcast_to(s, (n,)) if s.size == 1 else s)
            if feeds[LIGHT_SCALE_NAME].shape != (n,):
                raise ValueError(f"light_scale: expected one value or {n}, got {s.size}")
        if self.world:
            if camera is None:
                raise ValueError(f"{self.path.name} uses encoding version 3: run() needs each frame's camera "
                                 "(its conditioning: NeuralGI.frame_inputs)")
            c = np.asarray(camera, np.float32).reshape(-1, CAMERA_PARAMS)
            if c.shape[0] not in (1, n):
                raise ValueError(f"camera: expected one or {n}, got {c.shape[0]}")
            feeds[CAMERA_NAME] = pad_camera_params(np.broadcast_to(c, (n, CAMERA_PARAMS)), width, height, self.multiple,
                                                   self.edge_guard)
        if self.lit:
            if light is None:
                raise ValueError(f"{self.path.name} uses encoding version 4: run() needs each frame's lights "
                                 "(its conditioning: NeuralGI.frame_inputs)")
            lights = LIGHT_PARAMS * self.light_count
            g = np.asarray(light, np.float32).reshape(-1, lights)
            if g.shape[0] not in (1, n):
                raise ValueError(f"light: expected one or {n}, got {g.shape[0]}")
            feeds[LIGHT_NAME] = np.ascontiguousarray(np.broadcast_to(g, (n, lights)))
        with (timer or self.timer).stage("inference"):
            (y,) = self.session.run([OUTPUT_NAME], feeds)
        y = crop_nhwc(y, height, width, self.multiple, self.edge_guard)
        self.nonfinite_outputs = count_nonfinite(y)
        # Radiance is never negative: the runtime clamps (models exported before the graph did so,
        # e.g. an indirect-target model's undershoot, would otherwise darken the composite below 0).
        # np.maximum keeps NaN, so a broken pixel stays broken.
        np.maximum(y, 0.0, out=y)
        return y[0] if single else y


def probe_frame(height: int, width: int) -> np.ndarray:
    """(1, H, W, 10) plausible raw buffers (depth 1..3, unit normals, mid-grey albedo, direct light in 0..1)."""
    yy, xx = np.mgrid[0:height, 0:width] / max(height, width, 1)
    normal = np.stack([xx - 0.5, yy - 0.5, np.ones_like(xx)], -1)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    albedo = np.stack([0.3 + 0.4 * xx, 0.5 + 0.0 * yy, 0.7 - 0.4 * yy], -1)
    direct = albedo * (0.5 + 0.5 * np.sin(6.0 * xx) * np.cos(4.0 * yy))[..., None]
    frame = np.concatenate([(1.0 + 2.0 * xx)[..., None], normal, albedo, direct], -1)
    return np.ascontiguousarray(frame[None], dtype=np.float32)


def probe(model: "NeuralGI") -> None:
    """Refuse a model whose graph yields NaN/Inf radiance on a plausible probe frame (broken weights, an
    fp16 overflow), before the viewer or the benchmark shows or times it: through ``model.run``, so the
    probe is padded, laid out and light-scaled as every frame is."""
    w, h = (min(int(d), 64) for d in model.resolution)
    camera = {"position": (0.0, 0.0, 4.0), "target": (0.0, 0.0, 0.0), "up": (0.0, 1.0, 0.0), "fov": 45.0}
    from diviewer.contract.conditioning import stand_in

    try:  # light scale 1, suns straight down, as the model's encoding takes them
        model.run(probe_frame(h, w)[0], **stand_in(model.encoding, (w, h), camera=camera).inputs())
    except Exception as exc:  # onnxruntime raises its own types for a graph that cannot run
        raise DiviewerError(f"the model cannot run on a {w}x{h} probe frame: {exc}", path=model.path) from exc
    bad = model.nonfinite_outputs  # counted before the clamp at 0, which would hide a -Inf
    if bad:
        raise DiviewerError(f"the model's graph yields {bad} NaN/Inf values on a {w}x{h} probe frame of plausible "
                            f"buffers: the model is broken (re-export it from a sound checkpoint)", path=model.path)


def count_nonfinite(x: np.ndarray) -> int:
    """How many values of ``x`` are NaN or infinite, in one pass without a mask when there are none."""
    # A float64 sum of float32 values cannot overflow, and it is NaN/Inf exactly when an element is.
    with np.errstate(invalid="ignore", over="ignore"):  # inf + -inf is the NaN this looks for, not a fault
        total = np.add.reduce(x, axis=None, dtype=np.float64)
    if np.isfinite(total):
        return 0
    return int(x.size - np.count_nonzero(np.isfinite(x)))


def pack_buffers(frame: dict[str, np.ndarray]) -> np.ndarray:
    """GL frame buffers (depth (H, W), others (H, W, 3)) to the model's (H, W, 10) input, on the CPU."""
    parts = [frame[name].reshape(*frame[name].shape[:2], n) for name, n in INPUT_CHANNELS]
    return np.ascontiguousarray(np.concatenate(parts, axis=-1), dtype=np.float32)


__all__ = ["NeuralGI", "pack_buffers", "read_metadata", "check_compatible", "choose_providers", "INPUT_NAME",
           "LIGHT_SCALE_NAME", "OUTPUT_NAME", "META_KEY", "OUTPUT_CHANNELS"]
