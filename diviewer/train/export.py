"""`diviewer export`: a checkpoint's generator to ONNX with encoding and decoding inside the graph,
verified against PyTorch in onnxruntime before it is written.

The graph follows the model contract in diviewer/contract/runtime.py: input ``buffers`` (N, H, W, 10) raw
linear buffers (or (N, 10, H, W) with ``--layout NCHW``), for encoding version 2 a second input
``light_scale`` (N,), output ``radiance`` (N, H, W, 3) linear radiance of the final image. For a model
of the ``indirect`` target the exact GL direct light is added inside the graph, so the runtime never
needs to know the target. Spatial size is dynamic (multiples of 2**levels; the runtime pads any other)
and so is the batch; the metadata records the resolution the model was trained at. The graph is the
lean one of `diviewer.train.graph`, checked against training's own functions before it is written.
"""

from __future__ import annotations

import hashlib
import io
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from diviewer import imageio
from diviewer.contract.encoding import INPUT_CHANNELS, channel_slices
from diviewer.errors import DiviewerError, missing_extra
from diviewer.metrics import psnr
from diviewer.outputs import check_output_file, dumps, staged
from diviewer.contract.padding import crop_nhwc, pad_camera_params, pad_nhwc
from diviewer.contract.conditioning import stacked
from diviewer.provenance import versions
from diviewer.contract.runtime import (CAMERA_NAME, INPUT_NAME, LIGHT_NAME, LIGHT_SCALE_NAME, META_KEY, MODEL_FORMAT,
                              OUTPUT_NAME)
from diviewer.contract.weights import store_weights_half, store_weights_int8
from diviewer.train.checks import (FP16_TOLERANCE, HALF_WEIGHTS_TOLERANCE, INT8_WEIGHTS_TOLERANCE, extreme_frame,
                                   refuse_broken, refuse_departures, verification_line)

OPSET = 17
FP32_TOLERANCE = 1e-4
"""fp32 export fails if max |onnx - torch| exceeds this fraction of the reference's peak radiance."""


@dataclass(frozen=True)
class ExportSettings:
    """How a checkpoint is exported."""

    fp16: bool = False
    """Store weights and run the generator in float16; encoding and decoding stay float32."""
    half_weights: bool = False
    """Store the float32 weights as float16 in the file and run in float32: each weight tensor is cast back as
    onnxruntime loads the model (it folds the casts), so the file is half the size and the arithmetic is the
    float32 graph's, on weights rounded to 11 significant bits (`HALF_WEIGHTS_TOLERANCE`). Not with ``fp16``,
    whose weights are float16 already."""
    int8_weights: bool = False
    """Store the inner convolutions' weights as int8 with a float32 scale per output channel, the rest as
    ``half_weights`` stores them, and run in float32: onnxruntime folds the casts and scales as it loads the model,
    so the file is about a quarter of float32's and the arithmetic the float32 graph's, on weights rounded to 1/254
    of their channel's range (`INT8_WEIGHTS_TOLERANCE`; `diviewer.contract.weights.store_weights_int8`)."""
    verify_frames: int = 4
    """Frames compared between onnxruntime and PyTorch before the file is written."""
    layout: str = "NHWC"
    """The graph's input layout (the metadata's ``layout``): "NHWC", as the GL pack writes it (one transpose of
    the ten input channels inside the graph: measured within noise of "NCHW" on the 2-core machine, K=8 at
    128x128), or "NCHW" for a caller that packs channel-first (the runtime transposes NHWC buffers for it)."""

    def __post_init__(self):
        if self.fp16 and self.half_weights:
            raise DiviewerError("half_weights stores float32 weights as float16; an fp16 export's are float16 "
                                "already: give one of the two", field="half_weights")
        if self.int8_weights and (self.fp16 or self.half_weights):
            raise DiviewerError("int8_weights stores a float32 generator's weights as int8 and float16: not with "
                                f"{'fp16' if self.fp16 else 'half_weights'}; give one of them", field="int8_weights")

    @property
    def stored(self) -> str:
        """How the file stores the weights, the card's ``weights``: fp32, fp16 or int8."""
        return "int8" if self.int8_weights else "fp16" if self.fp16 or self.half_weights else "fp32"


def _torch():
    try:
        import torch
    except ImportError as exc:
        raise missing_extra("torch") from exc
    return torch


def gi_module(netG, encoding, meta: dict, fp16: bool = False, layout: str = "NHWC", lean: bool = True):
    """The exported computation as a torch module: raw buffers (+ light scale for encoding version 2) ->
    linear radiance NHWC; ``lean`` the graph export writes, else training's own functions (the reference)."""
    _torch()
    from diviewer.train.graph import LeanGI, ReferenceGI

    module = LeanGI(netG, encoding, meta, fp16, layout) if lean else ReferenceGI(netG, encoding, meta, fp16)
    return module.eval()


def onnx_bytes(module, example, light_scale=None, camera=None, light=None) -> bytes:
    """`module` (buffers [, light_scale [, camera [, light]]] -> NHWC radiance) as ONNX bytes: the legacy
    TorchScript exporter at `OPSET`, dynamic batch, height and width. `example` is a (1, H, W, 10) or (1, 10, H, W)
    float32 tensor; ``camera`` (encoding 3) a (1, CAMERA_PARAMS) one; ``light`` (encoding 4) a (1, 3 L) one."""
    torch = _torch()
    buf = io.BytesIO()
    layout = getattr(module, "layout", "NHWC")
    hw = {0: "N", 2: "H", 3: "W"} if layout == "NCHW" else {0: "N", 1: "H", 2: "W"}
    names, args, axes = [INPUT_NAME], (example,), {INPUT_NAME: hw, OUTPUT_NAME: {0: "N", 1: "H", 2: "W"}}
    if light_scale is not None:
        names, args = names + [LIGHT_SCALE_NAME], (example, light_scale)
        axes[LIGHT_SCALE_NAME] = {0: "N"}
    if camera is not None:
        names, args = names + [CAMERA_NAME], (*args, camera)
        axes[CAMERA_NAME] = {0: "N"}
    if light is not None:
        names, args = names + [LIGHT_NAME], (*args, light)
        axes[LIGHT_NAME] = {0: "N"}
    with torch.no_grad(), warnings.catch_warnings():
        # InstanceNorm without running statistics normalises with each image's own statistics in
        # eval mode too, which is what it should export; the exporter warns about exactly that.
        warnings.filterwarnings("ignore", message=r".*operator 'instance_norm' is set to train=True")
        # The tracer warns of every Python-side shape computation (the padding to the stride, the world planes'
        # sizes); the graph is checked against PyTorch on real and extreme frames after export, which is what
        # tells whether those computations were captured right, so the warnings are noise to a user.
        warnings.filterwarnings("ignore", category=torch.jit.TracerWarning)
        warnings.simplefilter("ignore", DeprecationWarning)  # the TorchScript exporter, chosen for its If (graph.py)
        torch.onnx.export(module, args, buf, input_names=names, output_names=[OUTPUT_NAME],
                          opset_version=OPSET, dynamo=False, dynamic_axes=axes)
    return buf.getvalue()


def _verification_frames(encoding, data_dir: str | None, n: int, res: tuple[int, int]) -> tuple[np.ndarray, str, list]:
    """Frames to verify an export on, each with its conditioning under ``encoding``
    (`diviewer.contract.conditioning`): the training dataset's val split (each frame's from its stored
    configuration) when it is there and its frames have as many lights as the model takes, else procedural
    buffers (each a `stand_in`'s: a light scale of 0.5 to 2, the stand-in camera, suns at a few directions)."""
    from diviewer.contract.conditioning import conditioning, has_lights_for, needs_scene, stand_in
    from diviewer.data.dataset import Dataset

    if data_dir and (Path(data_dir) / "manifest.json").is_file():
        ds = Dataset(data_dir)
        idx = (ds.indices("val") or ds.indices())[:n]
        configs = {f["index"]: f.get("config") for f in ds.frames}
        if idx and all(has_lights_for(configs[i], encoding) for i in idx):
            frames = []
            for i in idx:
                f = ds.load(i)
                frames.append(np.concatenate([f[name].reshape(*f[name].shape[:2], n) for name, n in INPUT_CHANNELS], -1))
            from diviewer.data.scales import dataset_scene

            scene = dataset_scene(ds) if needs_scene(encoding) else None
            size = (frames[0].shape[1], frames[0].shape[0])
            return (np.stack(frames).astype(np.float32), f"{len(idx)} frames of {data_dir}",
                    [conditioning(scene, configs[i], size, encoding, path=ds.root / "manifest.json") for i in idx])
    # No dataset: smooth synthetic buffers with plausible ranges (depth 1..far, unit normals).
    rng = np.random.default_rng(0)
    w, h = res
    yy, xx = np.mgrid[0:h, 0:w] / max(w, h)
    frames = []
    for _ in range(n):
        a = rng.uniform(0.5, 2.0, 4)
        depth = 1.0 + a[0] * (1 + np.sin(3 * xx + a[1]))
        normal = np.stack([np.sin(xx * a[2]), np.cos(yy * a[3]), np.ones_like(xx)], -1)
        normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
        albedo = np.stack([0.2 + 0.6 * xx, 0.5 + 0.0 * yy, 0.8 - 0.6 * yy], -1)
        direct = albedo * np.maximum(0, np.sin(5 * xx * a[0]) * np.cos(4 * yy * a[1]))[..., None] * a[2]
        frames.append(np.concatenate([depth[..., None], normal, albedo, direct], -1))
    scales = rng.uniform(0.5, 2.0, n).astype(np.float32)  # drawn last: the frames are the same for every encoding
    conds = [stand_in(encoding, res, light_scale=s, sun=(np.sin(t), -1.0, np.cos(t)))
             for s, t in zip(scales, np.linspace(0.0, 2.0, n))]
    return np.stack(frames).astype(np.float32), f"{n} synthetic frames (dataset {data_dir} not found)", conds


def check_export_paths(ckpt_path: Path, out: Path) -> None:
    """Refuse, before any work, an --out that would overwrite the checkpoint or be overwritten by the card."""
    if not ckpt_path.is_file():
        raise DiviewerError(f"checkpoint not found: {ckpt_path}", field="checkpoint")
    card = out.with_suffix(".json")
    check_output_file(out, "--out", protect=(ckpt_path,), suffix=".onnx", replaces="model")
    check_output_file(card, "--out", protect=(ckpt_path,), replaces="model")


def run_session(session, frames: np.ndarray, scales: np.ndarray | None, layout: str,
                cams: np.ndarray | None = None, lights: np.ndarray | None = None) -> np.ndarray:
    """An export's onnxruntime session on NHWC frames (one at a time), as the runtime feeds it."""
    out = []
    for k, f in enumerate(frames):
        feed = {INPUT_NAME: np.ascontiguousarray(f[None].transpose(0, 3, 1, 2) if layout == "NCHW" else f[None])}
        if scales is not None:
            feed[LIGHT_SCALE_NAME] = scales[k:k + 1].astype(np.float32)
        if cams is not None:
            feed[CAMERA_NAME] = cams[k:k + 1].astype(np.float32)
        if lights is not None:
            feed[LIGHT_NAME] = lights[k:k + 1].astype(np.float32)
        out.append(session.run([OUTPUT_NAME], feed)[0])
    return np.concatenate(out)


def verified_onnx(make_netG, encoding, meta: dict, settings: ExportSettings, frames: np.ndarray,
                  scales: np.ndarray | None, source: str, out: Path, log=print, weights_from: Path | None = None,
                  cams: np.ndarray | None = None, lights: np.ndarray | None = None,
                  crop: tuple[int, int, int] | None = None):
    """The lean graph of ``make_netG()`` as an ONNX model, checked in onnxruntime against training's own
    functions in PyTorch (`diviewer.train.graph.ReferenceGI`, fp32) before anything is written: on the
    frames, on a copy with NaN/Inf/extreme values in every channel, and, for encoding 2, at zero light
    (exactly 0) and twice the light (twice the output). Broken weights or a constant/non-finite output are
    refused first (`diviewer.train.checks`), naming ``weights_from`` (the checkpoint; default ``out``). ``crop``:
    (height, width, multiple) of frames padded to the model's stride: scored on their own pixels only.
    Returns (model, the card's verification record); raises DiviewerError where a check fails."""
    torch = _torch()
    import onnx
    import onnxruntime as ort

    netG = make_netG()
    ref_module = gi_module(netG, encoding, meta, lean=False)
    # broken weights, or an output that is constant or non-finite: refused, naming the checkpoint
    reference = refuse_broken(netG, ref_module, frames, settings.stored != "fp32",
                              weights_from or out, scales, cams, lights)
    ext = extreme_frame(frames[0])[None]
    def head(a):  # a per-frame input's first row (encoding 2's light scale, 3's camera, 4's lights), or None
        return None if a is None else a[:1]

    first = [None if a is None else torch.from_numpy(head(a).astype(np.float32)) for a in (scales, cams, lights)]
    with torch.no_grad():
        ref_ext = ref_module(torch.from_numpy(ext), *first).numpy()
        module = gi_module(make_netG(), encoding, meta, fp16=settings.fp16, layout=settings.layout)
    example = torch.from_numpy(frames[:1])
    example = example.permute(0, 3, 1, 2).contiguous() if settings.layout == "NCHW" else example
    data = onnx_bytes(module, example, *first)
    model = onnx.load_from_string(data)
    if settings.half_weights or settings.int8_weights:  # verified as written: the stored weights, cast back
        (store_weights_int8 if settings.int8_weights else store_weights_half)(model)
        data = model.SerializeToString()
    tolerance = FP16_TOLERANCE if settings.fp16 else {"fp32": FP32_TOLERANCE, "fp16": HALF_WEIGHTS_TOLERANCE,
                                                      "int8": INT8_WEIGHTS_TOLERANCE}[settings.stored]
    session = ort.InferenceSession(data, providers=["CPUExecutionProvider"])
    got = run_session(session, frames, scales, settings.layout, cams, lights)
    got_ext = run_session(session, ext, head(scales), settings.layout, head(cams), head(lights))
    # compared on the frames' own pixels, as the runtime crops them, not on the stride's padding
    shown, ref_shown = (got, reference) if crop is None else (crop_nhwc(a, *crop) for a in (got, reference))
    diff = np.abs(shown.astype(np.float64) - ref_shown)
    peak = float(np.abs(ref_shown).max()) or 1.0
    both = np.isfinite(got_ext) & np.isfinite(ref_ext)
    ext_diff = float(np.abs(got_ext[both].astype(np.float64) - ref_ext[both]).max()) if both.any() else 0.0
    check = {
        "frames": source, "layout": settings.layout,
        "max_abs_diff": float(diff.max()), "mean_abs_diff": float(diff.mean()),
        "max_rel_to_peak": float(diff.max() / peak),
        "psnr_db": float(np.mean([psnr(g, r, peak=peak) for g, r in zip(shown, ref_shown)])),
        "onnx_finite": bool(np.isfinite(got).all()),
        "extremes_same_nonfinite": bool(np.array_equal(np.isfinite(got_ext), np.isfinite(ref_ext))),
        "extremes_max_rel_to_peak": ext_diff / peak,
        "tolerance_rel_to_peak": tolerance,
    }
    precision = "fp16" if settings.fp16 else "fp32"
    if scales is not None:
        check.update(_light_checks(session, frames, scales, got, peak, settings.layout, precision, out, cams,
                                   lights))
    log(verification_line(check, precision))
    refuse_departures(check, reference, settings.fp16, settings.stored, precision, out)
    return model, check


def _light_checks(session, frames: np.ndarray, scales: np.ndarray, got: np.ndarray, peak: float, layout: str,
                  precision: str, out: Path, cams: np.ndarray | None = None,
                  lights: np.ndarray | None = None) -> dict:
    """Encoding 2 on the exported graph: zero light gives exactly 0 (refused otherwise), twice the light
    twice the output (recorded)."""
    dark = frames.copy()
    dark[..., channel_slices()["direct"]] = 0.0
    zero = run_session(session, dark, np.zeros_like(scales), layout, cams, lights)
    bright = frames.copy()
    bright[..., channel_slices()["direct"]] *= 2.0
    twice = run_session(session, bright, 2.0 * scales, layout, cams, lights)
    check = {"zero_light_max": float(np.abs(zero).max()),
             "twice_light_max_rel_to_peak": float(np.abs(twice - 2.0 * got).max() / (2.0 * peak))}
    if check["zero_light_max"] != 0.0:
        raise DiviewerError(f"the {precision} ONNX model is not black at zero light (max "
                            f"{check['zero_light_max']:.3g}); not written", path=out)
    return check


def export(ckpt_path: str | Path, out: str | Path, settings: ExportSettings = ExportSettings(), log=print) -> dict:
    """Export, verify, and write the model and its model card (``out`` with .json); returns the card."""
    _torch()
    import onnx

    from diviewer.train.checkpoint import build_generator_from_checkpoint, load_checkpoint

    ckpt_path, out = Path(ckpt_path), Path(out)
    check_export_paths(ckpt_path, out)
    ckpt = load_checkpoint(ckpt_path)
    netG, encoding, meta = build_generator_from_checkpoint(ckpt)
    levels = int(meta["model_args"]["levels"])
    res = tuple(int(x) for x in meta["resolution"])
    frames, source, conds = _verification_frames(encoding, meta["config"].get("data"), settings.verify_frames, res)
    scales, cams, lights = stacked(conds)
    if cams is not None:  # the cameras of the padded frames, as the runtime shifts them
        cams = pad_camera_params(cams, frames.shape[2], frames.shape[1], 2 ** levels)
    shown = (frames.shape[1], frames.shape[2], 2 ** levels)
    frames = pad_nhwc(frames, 2 ** levels)  # a capture of another shape (e.g. 228x128): padded as the runtime pads
    model, check = verified_onnx(lambda: build_generator_from_checkpoint(ckpt)[0], encoding, meta, settings, frames,
                                 scales, source, out, log, weights_from=ckpt_path, cams=cams, lights=lights,
                                 crop=shown)
    precision = "fp16" if settings.fp16 else "fp32"
    card = {
        "format": MODEL_FORMAT,
        "input": INPUT_NAME,
        "output": OUTPUT_NAME,
        "layout": settings.layout,
        "channels": [list(c) for c in INPUT_CHANNELS],
        "resolution": list(res),
        "multiple": 2 ** levels,
        "K": int(meta["K"]),
        "levels": levels,
        # absent from checkpoints made before these options existed, which were transpose/batch
        "upsample": meta["model_args"].get("upsample", "transpose"),
        "norm": meta["model_args"].get("norm", "batch"),
        # Fourier octaves of the world position into the first layer (absent: none, as every model before them)
        **({"world_frequencies": meta["model_args"]["frequencies"]} if meta["model_args"].get("frequencies") else {}),
        "target": meta["target"],
        "divide_albedo": meta["divide_albedo"],
        "encoding": encoding.to_dict(),
        "precision": precision,
        "weights": settings.stored,
        "scene": meta["scene"],
        "scene_hash": meta["scene_hash"],
        "dataset_hash": meta["dataset_hash"],
        "direct_samples": int(meta.get("direct_samples", 1)),
        # a refined truth's real samples per pixel over the train frames (`checkpoint.truth_spp`); absent: as captured
        **({"truth_spp": meta["truth_spp"]} if meta.get("truth_spp") else {}),
        "epochs": int(meta["epoch"]),
        "steps": int(meta["step"]),
        "validation": meta["val"],
        "checkpoint_sha256": hashlib.sha256(ckpt_path.read_bytes()).hexdigest(),
        "trained_with": meta["versions"],
        "trained_on": meta.get("trained_on"),
        "exported_with": versions(),
        "verification": check,
        "opset": OPSET,
        "recipe": _recipe(meta),
    }
    onnx.helper.set_model_props(model, {META_KEY: dumps(card, sort_keys=True)})
    model.producer_name, model.producer_version = "diviewer", card["exported_with"]["diviewer"]
    with staged() as stage:  # the model and its card land together, or neither does
        onnx.save(model, str(stage(out)))
        imageio.write_text(stage(out.with_suffix(".json")), dumps(card, indent=2, sort_keys=True))
    log(f"wrote {out} ({out.stat().st_size / 1e6:.2f} MB) and {out.with_suffix('.json').name}")
    return card


_RUN_ONLY = ("data", "out", "max_steps", "device", "num_workers", "precision")
"""TrainConfig fields that describe one invocation on one machine, not how the model was made."""


def _recipe(meta: dict) -> dict:
    """How the model was made, for the card: capture settings, training settings, network settings
    (`diviewer build` rebuilds a shipped model from its recipe file). A warm-started run's recipe
    holds its parent's under ``init`` (with the parent checkpoint's hash and step), recursively; the
    parent's path on the machine that trained it is not a recipe."""
    rec = {"capture": meta.get("capture"),
           "train": {k: v for k, v in meta["config"].items() if k not in _RUN_ONLY and k != "init_from"},
           "net": meta["net_config"], "loss": meta.get("loss_config")}
    init = meta.get("init")
    if init:
        rec["init"] = {"checkpoint_sha256": init["checkpoint_sha256"], "step": init["step"],
                       "dataset_hash": init["dataset_hash"], "train_frames": init["train_frames"],
                       "recipe": _recipe(init["meta"])}
    return rec


def _hardware(t: dict | None) -> str:
    """A card's `trained_on` in words."""
    if not t:
        return "not recorded"
    words = f"{t['device']}" + (f" ({t['name']})" if t.get("name") else "") + f", {t['autocast']}"
    if t.get("torch_threads"):
        words += f", {t['torch_threads']} torch thread{'s' if t['torch_threads'] > 1 else ''}"
    return words + (f"; before a resume: {_hardware(t['before'])}" if t.get("before") else "")


def info(path: str | Path) -> str:
    """A readable summary of a model's metadata (`diviewer export --info`)."""
    from diviewer.contract.runtime import model_edge_guard, read_metadata

    m = read_metadata(path)
    if m.get("kind") == "linear_baseline":
        return "\n".join([f"{path}", f"  scene        {m['scene']} (scene file sha256 {m['scene_hash'][:16]}...)",
                          f"  baseline     {m['description']}",
                          f"  parameters   {m['parameters']}, fitted on {m['fit']['frames']} frames "
                          f"({m['fit']['split']} split of {m['fit']['data']}), train RMSE {m['fit']['train_rmse']:.4g}"])
    val = m.get("validation") or {}
    lines = [f"{path}",
             f"  scene        {m['scene']} (scene file sha256 {m['scene_hash'][:16]}...)",
             f"  network      U-Net K={m['K']} levels={m['levels']} upsample={m.get('upsample', 'transpose')} "
             f"norm={m.get('norm', 'batch')}"
             + (f" world-frequencies={m['world_frequencies']}" if m.get("world_frequencies") else "")
             + f" ({m['precision']}"
             f"{', weights stored ' + m['weights'] if m.get('weights', 'fp32') != m['precision'] else ''}), "
             f"target {m['target']}"
             + (" / albedo" if m.get("divide_albedo") else ""),
             f"  trained at   {m['resolution'][0]}x{m['resolution'][1]}; runs any size, padded to multiples of "
             f"{m['multiple']}" + (f" with {g} columns a side at least" if (g := model_edge_guard(m)) else ""),
             f"  trained on   {_hardware(m.get('trained_on'))}",
             f"  training     {m.get('epochs')} epochs, {m.get('steps')} steps, dataset {m['dataset_hash'][:16]}...",
             f"  input        {m['input']} {m['layout']} channels "
             + ", ".join(f"{n}({c})" for n, c in m["channels"])
             + (" + light_scale (N,): linear in the light" if int(m["encoding"].get("version", 1)) >= 2 else ""),
             f"  output       {m['output']} (N, H, W, 3) linear radiance",
             "  encoding     " + ", ".join(f"{k}={v}" for k, v in m["encoding"].items())]
    if val:
        lines.append("  validation   " + ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                                                for k, v in val.items()))
    if "verification" in m:
        v = m["verification"]
        lines.append(f"  verified     max |onnx - torch| {v['max_abs_diff']:.3g}, PSNR {v['psnr_db']:.1f} dB on {v['frames']}")
    lines.append(f"  exported by  diviewer {m.get('exported_with', {}).get('diviewer', '?')}")
    return "\n".join(lines)
