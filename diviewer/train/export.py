"""`diviewer export`: a checkpoint's generator to ONNX with encoding and decoding inside the graph,
verified against PyTorch in onnxruntime before it is written.

The graph follows the model contract in diviewer/runtime.py: input ``buffers`` (N, H, W, 10) raw
linear buffers, output ``radiance`` (N, H, W, 3) linear radiance of the final image. For a model of
the ``indirect`` target the exact GL direct light is added inside the graph, so the runtime never
needs to know the target. Spatial size is dynamic (any multiple of 2**levels) and so is the batch;
the metadata records the resolution the model was trained at, which the viewer uses.
"""

from __future__ import annotations

import hashlib
import io
import json
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from diviewer import imageio
from diviewer.encoding import INPUT_CHANNELS, channel_slices
from diviewer.errors import DiviewerError, missing_extra
from diviewer.metrics import psnr
from diviewer.outputs import check_output_file, dumps, staged
from diviewer.provenance import versions
from diviewer.runtime import INPUT_NAME, META_KEY, MODEL_FORMAT, OUTPUT_NAME
from diviewer.train.checks import FP16_TOLERANCE, refuse_broken

OPSET = 17
FP32_TOLERANCE = 1e-4
"""fp32 export fails if max |onnx - torch| exceeds this fraction of the reference's peak radiance."""


@dataclass(frozen=True)
class ExportSettings:
    """How a checkpoint is exported."""

    fp16: bool = False
    """Store weights and run the generator in float16; encoding and decoding stay float32."""
    verify_frames: int = 4
    """Frames compared between onnxruntime and PyTorch before the file is written."""


def _torch():
    try:
        import torch
    except ImportError as exc:
        raise missing_extra("torch") from exc
    return torch


def gi_module(netG, encoding, meta: dict, fp16: bool = False):
    """The exported computation as a torch module: raw NHWC buffers -> linear radiance NHWC."""
    torch = _torch()
    from diviewer.train.encoding_torch import decode_radiance, encode_inputs
    from diviewer.train.targets import compose_radiance

    class GIModel(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.netG = netG.half() if fp16 else netG

        def forward(self, buffers):
            x = buffers.permute(0, 3, 1, 2)
            depth, normal, albedo, direct = (x[:, channel_slices()[k]] for k in ("depth", "normal", "albedo", "direct"))
            inp = encode_inputs(depth, normal, albedo, direct, encoding, channel_axis=1)
            y = self.netG(inp.half() if fp16 else inp)
            radiance = decode_radiance(y.float() if fp16 else y, encoding)
            out = compose_radiance(radiance, direct, albedo, meta["target"], meta["divide_albedo"])
            return out.permute(0, 2, 3, 1)  # clamped at 0 by compose_radiance

    return GIModel().eval()


def onnx_bytes(module, example) -> bytes:
    """`module` (NHWC buffers -> NHWC radiance) as ONNX bytes: the legacy TorchScript exporter at
    `OPSET`, dynamic batch, height and width. `example` is a (1, H, W, 10) float32 tensor."""
    torch = _torch()
    buf = io.BytesIO()
    with torch.no_grad(), warnings.catch_warnings():
        # InstanceNorm without running statistics normalises with each image's own statistics in
        # eval mode too, which is what it should export; the exporter warns about exactly that.
        warnings.filterwarnings("ignore", message=r".*operator 'instance_norm' is set to train=True")
        torch.onnx.export(module, (example,), buf, input_names=[INPUT_NAME], output_names=[OUTPUT_NAME],
                          opset_version=OPSET, dynamo=False,
                          dynamic_axes={INPUT_NAME: {0: "N", 1: "H", 2: "W"}, OUTPUT_NAME: {0: "N", 1: "H", 2: "W"}})
    return buf.getvalue()


def _verification_frames(meta: dict, data_dir: str | None, n: int, res: tuple[int, int]) -> tuple[np.ndarray, str]:
    """Real frames from the training dataset's val split when it is there, else procedural buffers."""
    from diviewer.data.dataset import Dataset

    if data_dir and (Path(data_dir) / "manifest.json").is_file():
        ds = Dataset(data_dir)
        idx = (ds.indices("val") or ds.indices())[:n]
        if idx:
            frames = []
            for i in idx:
                f = ds.load(i)
                frames.append(np.concatenate([f[name].reshape(*f[name].shape[:2], n) for name, n in INPUT_CHANNELS], -1))
            return np.stack(frames).astype(np.float32), f"{len(idx)} frames of {data_dir}"
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
    return np.stack(frames).astype(np.float32), f"{n} synthetic frames (dataset {data_dir} not found)"


def check_export_paths(ckpt_path: Path, out: Path) -> None:
    """Refuse, before any work, an --out that would overwrite the checkpoint or be overwritten by the card."""
    if not ckpt_path.is_file():
        raise DiviewerError(f"checkpoint not found: {ckpt_path}", field="checkpoint")
    card = out.with_suffix(".json")
    check_output_file(out, "--out", protect=(ckpt_path,), suffix=".onnx", replaces="model")
    check_output_file(card, "--out", protect=(ckpt_path,), replaces="model")


def export(ckpt_path: str | Path, out: str | Path, settings: ExportSettings = ExportSettings(), log=print) -> dict:
    """Export, verify, and write the model and its model card (``out`` with .json); returns the card."""
    torch = _torch()
    import onnx
    import onnxruntime as ort

    from diviewer.train.checkpoint import build_generator_from_checkpoint, load_checkpoint

    ckpt_path, out = Path(ckpt_path), Path(out)
    check_export_paths(ckpt_path, out)
    ckpt = load_checkpoint(ckpt_path)
    netG, encoding, meta = build_generator_from_checkpoint(ckpt)
    levels = int(meta["model_args"]["levels"])
    res = tuple(int(x) for x in meta["resolution"])
    ref_module = gi_module(netG, encoding, meta, fp16=False)
    frames, source = _verification_frames(meta, meta["config"].get("data"), settings.verify_frames, res)
    reference = refuse_broken(netG, ref_module, frames, settings.fp16, ckpt_path)
    with torch.no_grad():
        module = gi_module(build_generator_from_checkpoint(ckpt)[0], encoding, meta, fp16=settings.fp16)
    data = onnx_bytes(module, torch.from_numpy(frames[:1]))
    model = onnx.load_from_string(data)
    session = ort.InferenceSession(data, providers=["CPUExecutionProvider"])
    got = np.concatenate([session.run([OUTPUT_NAME], {INPUT_NAME: f[None]})[0] for f in frames])
    diff = np.abs(got.astype(np.float64) - reference)
    peak = float(np.abs(reference).max()) or 1.0
    check = {
        "frames": source,
        "max_abs_diff": float(diff.max()),
        "mean_abs_diff": float(diff.mean()),
        "max_rel_to_peak": float(diff.max() / peak),
        "psnr_db": float(np.mean([psnr(g, r, peak=peak) for g, r in zip(got, reference)])),
        "onnx_finite": bool(np.isfinite(got).all()),
        "tolerance_rel_to_peak": FP16_TOLERANCE if settings.fp16 else FP32_TOLERANCE,
    }
    precision = "fp16" if settings.fp16 else "fp32"
    log(f"verify {precision} against torch on {source}: max |diff| {check['max_abs_diff']:.3g} "
        f"({check['max_rel_to_peak']:.2g} of peak {peak:.3g}), mean {check['mean_abs_diff']:.3g}, "
        f"PSNR {check['psnr_db']:.1f} dB")
    if np.isfinite(reference).all() and not check["onnx_finite"]:
        raise DiviewerError(f"the {precision} ONNX model produced NaN/Inf where PyTorch did not "
                            f"(overflow?); not written", path=out)
    tolerance = check["tolerance_rel_to_peak"]
    if not check["max_rel_to_peak"] <= tolerance:
        raise DiviewerError(f"the {precision} ONNX model differs from PyTorch by {check['max_rel_to_peak']:.2g} of "
                            f"peak (tolerance {tolerance}); not written", path=out)
    card = {
        "format": MODEL_FORMAT,
        "input": INPUT_NAME,
        "output": OUTPUT_NAME,
        "layout": "NHWC",
        "channels": [list(c) for c in INPUT_CHANNELS],
        "resolution": list(res),
        "multiple": 2 ** levels,
        "K": int(meta["K"]),
        "levels": levels,
        # absent from checkpoints made before these options existed, which were transpose/batch
        "upsample": meta["model_args"].get("upsample", "transpose"),
        "norm": meta["model_args"].get("norm", "batch"),
        "target": meta["target"],
        "divide_albedo": meta["divide_albedo"],
        "encoding": encoding.to_dict(),
        "precision": precision,
        "scene": meta["scene"],
        "scene_hash": meta["scene_hash"],
        "dataset_hash": meta["dataset_hash"],
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
    from diviewer.runtime import read_metadata

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
             f"norm={m.get('norm', 'batch')} ({m['precision']}), target {m['target']}"
             + (" / albedo" if m.get("divide_albedo") else ""),
             f"  trained at   {m['resolution'][0]}x{m['resolution'][1]}; sizes must be multiples of {m['multiple']}",
             f"  trained on   {_hardware(m.get('trained_on'))}",
             f"  training     {m.get('epochs')} epochs, {m.get('steps')} steps, dataset {m['dataset_hash'][:16]}...",
             f"  input        {m['input']} {m['layout']} channels "
             + ", ".join(f"{n}({c})" for n, c in m["channels"]),
             f"  output       {m['output']} (N, H, W, 3) linear radiance",
             f"  encoding     " + ", ".join(f"{k}={v}" for k, v in m["encoding"].items())]
    if val:
        lines.append("  validation   " + ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                                                for k, v in val.items()))
    if "verification" in m:
        v = m["verification"]
        lines.append(f"  verified     max |onnx - torch| {v['max_abs_diff']:.3g}, PSNR {v['psnr_db']:.1f} dB on {v['frames']}")
    lines.append(f"  exported by  diviewer {m.get('exported_with', {}).get('diviewer', '?')}")
    return "\n".join(lines)
