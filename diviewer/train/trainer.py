"""Train Deep Illumination's cGAN for one scene: pix2pix from G-buffers + direct light to the GI image.

Usage::

    diviewer train --data data/cornell --k 32 --epochs 50 --out runs/cornell_k32
    diviewer train --data data/cornell --out runs/cornell_k32 --resume      # continue exactly
    torchrun --standalone --nproc_per_node 4 -m diviewer.train.trainer --data data/cornell --out runs/c4

A run folder holds ``last.ckpt`` (every epoch, and wherever a run stops), ``best.ckpt`` (best
validation SSIM on tone-mapped images), ``metrics.csv`` (one row per epoch) and ``curves.png``.

Resume is exact (the same losses and weights as an uninterrupted run, bit for bit on one CPU): a
checkpoint holds both networks, both Adam states, the epoch and the step inside it, every process's
random state (torch, CUDA, numpy, python) and the loss sums of the unfinished epoch, and the data
order is a pure function of (seed, epoch) (`epoch_batches`). A first Ctrl-C or SIGTERM finishes the
current step, saves last.ckpt and stops; `max_steps` stops the same way.

No augmentation: a mirrored frame is a valid image only with the x component of the view-space
normals negated, and even then it shows a mirrored scene whose off-screen geometry (which bounces
light into the frame) is on the wrong side. The network learns one scene; flips would teach it two.

The file reads top to bottom: settings, what the network learns (targets, tone map, encoding),
data order, checkpoints, validation, the training loop, the command line. torch is imported
inside the functions, so the command line can be built (and `diviewer --help` runs) without it.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import math
import os
import random
import shutil
import signal
import sys
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from diviewer import imageio
from diviewer.errors import DiviewerError, missing_extra
from diviewer.metrics import tonemap  # noqa: F401  (re-exported: the validation tone map)
from diviewer.provenance import check_known_keys

if TYPE_CHECKING:
    import torch

    from diviewer.data.dataset import Dataset
    from diviewer.encoding import Encoding


@dataclass(frozen=True)
class TrainConfig:
    """Settings of one training run; recorded in every checkpoint (`to_dict`)."""

    data: Path
    """Dataset folder (`diviewer capture` output) with train and val frames."""

    out: Path
    """Run folder: checkpoints, metrics.csv, curves.png."""

    K: int = 32
    """Generator base width (pix2pix's ngf); the paper trains K = 32, 64, 128."""

    epochs: int = 50
    """Passes over the train split (the paper: 50)."""

    batch_size: int = 4
    """Frames per step (per process under torchrun); the paper: 4."""

    lr: float = 2e-4
    """Adam learning rate of both networks (pix2pix)."""

    beta1: float = 0.5
    """Adam beta1 (pix2pix: 0.5, which keeps GAN training stable)."""

    beta2: float = 0.999
    """Adam beta2."""

    lambda_L1: float = 100.0
    """Weight of the L1 term against the adversarial term (pix2pix)."""

    target: str = "full"
    """What netG predicts: "full" (the path-traced image) or "indirect" (pt - pt_direct, added to
    the GL direct light when composed)."""

    divide_albedo: bool = False
    """With target "indirect": predict indirect / max(albedo, ALBEDO_FLOOR) (texture-free, closer
    to irradiance) and multiply back when composing."""

    seed: int = 0
    """Seeds the weights, the data order and dropout; the same seed gives the same run."""

    dropout: float = 0.5
    """Dropout in the innermost generator decoders (pix2pix: 0.5)."""

    ndf: int = 64
    """Discriminator base width (the paper: 64)."""

    amp: bool = False
    """Mixed precision (float16 autocast + gradient scaling); CUDA only, ignored on CPU."""

    num_workers: int = 0
    """DataLoader workers. The train split lives in RAM, so workers only overlap the host-to-GPU
    copy with compute; 0 loads in the training process."""

    val_every: int = 1
    """Validate every this many epochs (and always after the last one and when a run stops)."""

    save_every: int = 0
    """Also write last.ckpt every this many steps inside an epoch (0: at epoch ends and stops only)."""

    max_steps: int | None = None
    """Stop after this many steps in total (smoke runs, tests); None trains all epochs."""

    device: str = "auto"
    """"auto" (CUDA if available, else CPU), "cpu", "cuda" or "cuda:N"."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "data", Path(self.data))
        object.__setattr__(self, "out", Path(self.out))

        def fail(name: str, message: str) -> None:
            raise DiviewerError(message, field=f"train.{name}")

        for name in ("K", "epochs", "batch_size", "ndf", "val_every"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                fail(name, f"must be a positive integer, got {v!r}")
        for name in ("num_workers", "save_every", "seed"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                fail(name, f"must be an integer >= 0, got {v!r}")
        if self.max_steps is not None and (isinstance(self.max_steps, bool) or not isinstance(self.max_steps, int)
                                           or self.max_steps < 1):
            fail("max_steps", f"must be a positive integer or None, got {self.max_steps!r}")
        if not (isinstance(self.lr, (int, float)) and math.isfinite(self.lr) and self.lr > 0):
            fail("lr", f"must be a positive number, got {self.lr!r}")
        for name in ("beta1", "beta2"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and 0.0 <= v < 1.0):
                fail(name, f"must be in [0, 1), got {v!r}")
        if not (isinstance(self.lambda_L1, (int, float)) and math.isfinite(self.lambda_L1) and self.lambda_L1 >= 0):
            fail("lambda_L1", f"must be a number >= 0, got {self.lambda_L1!r}")
        if not (isinstance(self.dropout, (int, float)) and 0.0 <= self.dropout < 1.0):
            fail("dropout", f"must be in [0, 1), got {self.dropout!r}")
        if self.target not in ("full", "indirect"):
            fail("target", f"must be 'full' or 'indirect', got {self.target!r}")
        if self.divide_albedo and self.target != "indirect":
            fail("divide_albedo", "only applies to target 'indirect' (use --target indirect)")
        cuda_n = self.device.startswith("cuda:") and self.device[5:].isdigit()
        if not (self.device in ("auto", "cpu", "cuda") or cuda_n):
            fail("device", f"must be auto, cpu, cuda or cuda:N, got {self.device!r}")

    def to_dict(self) -> dict[str, Any]:
        """Plain dict (paths as strings) for checkpoints."""
        d = dataclasses.asdict(self)
        d["data"], d["out"] = str(self.data), str(self.out)
        return d

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> TrainConfig:
        """Rebuild from `to_dict()` output; unknown keys are an error."""
        check_known_keys(cls, data, "train")
        return cls(**dict(data))


RESUME_FIXED: tuple[str, ...] = ("K", "batch_size", "lr", "beta1", "beta2", "lambda_L1", "target", "divide_albedo",
                                 "seed", "dropout", "ndf")
"""Settings a resumed run must share with its checkpoint (the others, e.g. epochs, may change)."""

RESUME_INHERITED: tuple[str, ...] = (*RESUME_FIXED, "epochs", "val_every", "save_every")
"""Settings `diviewer train --resume` takes from the checkpoint unless given again (max_steps, amp,
device and num_workers describe this invocation and this machine, so they are not inherited)."""

CHECKPOINT_FORMAT = "diviewer-checkpoint"
CHECKPOINT_VERSION = 1

ALBEDO_FLOOR: float = 0.05
"""With divide_albedo, indirect light is divided by max(albedo, ALBEDO_FLOOR) and multiplied back by
the same: exactly invertible, and dark or background pixels (albedo 0) do not amplify noise."""


METRIC_KEYS: tuple[str, ...] = ("mse", "psnr", "ssim", "mse_tm", "psnr_tm", "ssim_tm")
"""Validation metrics: on linear radiance, then on tone-mapped images (suffix _tm)."""

CSV_COLUMNS: tuple[str, ...] = ("epoch", "step", "loss_D", "loss_G_GAN", "loss_G_L1",
                                *(f"val_{k}" for k in METRIC_KEYS), "seconds")
"""metrics.csv columns: fractional epoch, global step, mean train losses over the epoch so far
(loss_G_L1 already times lambda_L1, as pix2pix reports it), validation metrics (empty when not
validated) and wall-clock seconds since the run began (summed over resumed parts)."""


def _require_torch():
    try:
        import torch
    except ImportError:
        raise missing_extra("torch") from None
    return torch


# ---------------------------------------------------------------------------------------------
# What the network learns: targets, composition, the tone map and the encoding


def target_radiance(pt: Any, pt_direct: Any, albedo: Any, target: str, divide_albedo: bool) -> Any:
    """Linear radiance netG learns to predict (before encoding), from path-traced ground truth."""
    if target == "full":
        return pt
    indirect = pt - pt_direct
    if divide_albedo:
        indirect = indirect / _albedo_floor(albedo)
    return indirect


def compose_radiance(pred: Any, direct: Any, albedo: Any, target: str, divide_albedo: bool) -> Any:
    """The displayed image from netG's decoded output: as is ("full"), or GL direct + indirect.

    Works on numpy arrays and torch tensors (ONNX: Max/Mul/Add), so the exporter can use it too.
    """
    if target == "full":
        return pred
    if divide_albedo:
        pred = pred * _albedo_floor(albedo)
    return direct + pred


def _albedo_floor(albedo: Any) -> Any:
    if type(albedo).__module__.startswith("torch"):
        return albedo.clamp(min=ALBEDO_FLOOR)
    return np.maximum(albedo, ALBEDO_FLOOR)


def fit_encoding(ds: Dataset, train_idx: list[int], train: np.ndarray) -> Encoding:
    """The dataset's encoding, fixed from the train split.

    exposure: `fit_exposure` over the train frames' GL direct light; depth_scale: the camera's far
    plane from the frame configurations (all visible geometry then maps into [0, 1]), else the
    largest train depth; radiance_max: the default.
    """
    from diviewer.encoding import Encoding, fit_exposure

    direct = ds.slices["direct"]
    exposure = fit_exposure([frame[..., direct] for frame in train])
    wanted = set(train_idx)
    fars = []
    for f in ds.frames:
        cam = (f.get("config") or {}).get("camera") or {}
        if f["index"] in wanted and isinstance(cam.get("far"), (int, float)) and cam["far"] > 0:
            fars.append(float(cam["far"]))
    if fars:
        depth_scale = max(fars)
    else:
        depth = train[..., ds.slices["depth"]].astype(np.float32)
        finite = depth[np.isfinite(depth) & (depth > 0)]
        depth_scale = float(finite.max()) if finite.size else 1.0
    return Encoding(exposure=float(exposure), depth_scale=float(depth_scale))


def split_batch(x16: torch.Tensor, slices: Mapping[str, slice], enc: Encoding,
                cfg: TrainConfig) -> dict[str, torch.Tensor]:
    """A stored (N, H, W, C) batch on the device -> real_A (encoded inputs), real_B (encoded target),
    and the raw NCHW planes the composition and the metrics need (direct, albedo, pt)."""
    from diviewer.encoding import encode_inputs, encode_radiance

    x = x16.permute(0, 3, 1, 2).float().contiguous()
    p = {name: x[:, s] for name, s in slices.items()}
    real_A = encode_inputs(p["depth"], p["normal"], p["albedo"], p["direct"], enc, channel_axis=1)
    target = target_radiance(p["pt"], p["pt_direct"], p["albedo"], cfg.target, cfg.divide_albedo)
    real_B = encode_radiance(target, enc)
    return {"real_A": real_A, "real_B": real_B, "direct": p["direct"], "albedo": p["albedo"], "pt": p["pt"]}


# ---------------------------------------------------------------------------------------------
# Processes, data order and random state


@dataclass(frozen=True)
class _Dist:
    """Where this process runs: rank and world size (1 without torchrun) and its device."""

    rank: int
    world: int
    device: Any
    initialized_here: bool

    @property
    def main(self) -> bool:
        return self.rank == 0


def _setup(cfg: TrainConfig) -> _Dist:
    """Pick the device; under torchrun (WORLD_SIZE > 1) join the process group (NCCL on GPUs, else gloo)."""
    import torch
    import torch.distributed as dist

    world = int(os.environ.get("WORLD_SIZE", "1"))
    rank = int(os.environ.get("RANK", "0"))
    local_rank = int(os.environ.get("LOCAL_RANK", "0"))
    want = cfg.device
    if want == "auto":
        want = "cuda" if torch.cuda.is_available() else "cpu"
    if want.startswith("cuda") and not torch.cuda.is_available():
        raise DiviewerError("CUDA is not available on this machine; use --device cpu (or auto)", field="--device")
    if world > 1:
        device = torch.device("cuda", local_rank) if want.startswith("cuda") else torch.device("cpu")
    else:
        device = torch.device(want)
    if device.type == "cuda":
        torch.cuda.set_device(device)
        torch.backends.cudnn.benchmark = True  # fixed input size: let cuDNN pick the fastest convolutions
    initialized = False
    if world > 1 and not dist.is_initialized():
        dist.init_process_group("nccl" if device.type == "cuda" else "gloo")
        initialized = True
    return _Dist(rank=rank, world=world, device=device, initialized_here=initialized)


def epoch_batches(n: int, epoch: int, seed: int, batch_size: int, rank: int = 0, world: int = 1) -> list[list[int]]:
    """This process's batches (indices into the train split) for one epoch: a pure function of its args.

    The order is DistributedSampler's (shuffled by seed + epoch, padded so every rank gets as many
    batches), so a resumed run only needs (epoch, batch) to continue the same order.
    """
    from torch.utils.data import DistributedSampler

    sampler = DistributedSampler(range(n), num_replicas=world, rank=rank, shuffle=True, seed=seed, drop_last=False)
    sampler.set_epoch(epoch)
    order = list(sampler)
    return [order[i:i + batch_size] for i in range(0, len(order), batch_size)]


class _InRam:
    """DataLoader dataset over the in-RAM split: one item is a whole batch, still float16."""

    def __init__(self, array: np.ndarray):
        self.array = array

    def __len__(self) -> int:
        return len(self.array)

    def __getitem__(self, idx: list[int]):
        import torch

        return torch.from_numpy(np.ascontiguousarray(self.array[idx]))


def _loader(array: np.ndarray, batches: list[list[int]], cfg: TrainConfig, dev: _Dist):
    import torch
    from torch.utils.data import DataLoader

    # batch_size=None: each sampler item is a list of indices and the dataset returns the batch.
    # The loader gets its own generator: by default it draws a worker seed from the global RNG,
    # which would shift dropout's random stream after a resume.
    return DataLoader(_InRam(array), sampler=batches, batch_size=None, num_workers=cfg.num_workers,
                      pin_memory=dev.device.type == "cuda", generator=torch.Generator().manual_seed(cfg.seed))


def _rng_state(device) -> dict[str, Any]:
    """This process's random state as tensors, lists and numbers (loadable with weights_only)."""
    import torch

    np_kind, np_keys, np_pos, np_has_gauss, np_gauss = np.random.get_state()
    py_version, py_state, py_gauss = random.getstate()
    return {
        "torch": torch.get_rng_state(),
        "cuda": torch.cuda.get_rng_state(device) if device.type == "cuda" else None,
        "numpy": {"kind": str(np_kind), "keys": [int(k) for k in np_keys], "pos": int(np_pos),
                  "has_gauss": int(np_has_gauss), "cached_gaussian": float(np_gauss)},
        "python": {"version": py_version, "state": list(py_state), "gauss_next": py_gauss},
    }


def _set_rng_state(state: Mapping[str, Any], device) -> None:
    import torch

    torch.set_rng_state(state["torch"])
    if device.type == "cuda" and state.get("cuda") is not None:
        torch.cuda.set_rng_state(state["cuda"], device)
    n = state["numpy"]
    np.random.set_state((n["kind"], np.asarray(n["keys"], dtype=np.uint32), n["pos"], n["has_gauss"],
                         n["cached_gaussian"]))
    p = state["python"]
    random.setstate((p["version"], tuple(p["state"]), p["gauss_next"]))


def _seed_all(seed: int) -> None:
    import torch

    torch.manual_seed(seed)
    np.random.seed(seed % 2**32)
    random.seed(seed)


# ---------------------------------------------------------------------------------------------
# Checkpoints


def _atomic_save(obj: Any, path: Path) -> None:
    """torch.save to a temporary file beside `path`, fsync, then rename: a reader never sees half a file."""
    import torch

    with imageio.atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            torch.save(obj, f)
            f.flush()
            os.fsync(f.fileno())


def load_checkpoint(path: str | Path, *, mmap: bool = False) -> dict[str, Any]:
    """Read a checkpoint written by `train` (weights_only: tensors and plain data only, on the CPU).

    Args:
        mmap: map the tensors instead of reading them (cheap when only the settings are needed).

    Raises:
        DiviewerError: naming the file when it is missing, truncated, not a checkpoint, or newer
            than this diviewer.
    """
    torch = _require_torch()
    path = Path(path)
    if not path.is_file():
        raise DiviewerError("checkpoint not found", path=path)
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True, mmap=mmap)
    except Exception as exc:  # truncated zip, foreign pickle, not a torch file at all
        raise DiviewerError(f"not a readable checkpoint ({type(exc).__name__}: {str(exc).splitlines()[0][:200]}); "
                            "it may be truncated or corrupt: use another checkpoint", path=path) from exc
    if not isinstance(ckpt, dict) or ckpt.get("format") != CHECKPOINT_FORMAT:
        raise DiviewerError(f"not a diviewer checkpoint (no format '{CHECKPOINT_FORMAT}')", path=path)
    if int(ckpt.get("format_version", 0)) > CHECKPOINT_VERSION:
        raise DiviewerError(f"checkpoint format {ckpt['format_version']} is newer than this diviewer reads "
                            f"({CHECKPOINT_VERSION}); upgrade diviewer", path=path, field="format_version")
    missing = [k for k in ("model_args", "net_config", "encoding", "config", "netG") if k not in ckpt]
    if missing:
        raise DiviewerError(f"checkpoint lacks {missing}", path=path)
    return ckpt


def build_generator_from_checkpoint(ckpt: Mapping[str, Any] | str | Path):
    """netG (eval mode, CPU) + its Encoding + what an exporter needs to know, from a checkpoint.

    Args:
        ckpt: a dict from `load_checkpoint`, or a checkpoint path.

    Returns:
        (netG, encoding, meta). meta holds target, divide_albedo, albedo_floor (how to compose the
        output: `compose_radiance`), resolution, K, scene, scene_hash, dataset_hash, epoch, step,
        val metrics, model_args, net_config, train config and versions.
    """
    _require_torch()
    from diviewer.encoding import Encoding
    from diviewer.train.networks import UnetGenerator

    if not isinstance(ckpt, Mapping):
        ckpt = load_checkpoint(ckpt)
    netG = UnetGenerator(**ckpt["model_args"])
    netG.load_state_dict(ckpt["netG"])
    netG.eval()
    encoding = Encoding.from_dict(ckpt["encoding"])
    config = ckpt["config"]
    meta = {
        "target": config["target"],
        "divide_albedo": bool(config["divide_albedo"]),
        "albedo_floor": ckpt.get("albedo_floor", ALBEDO_FLOOR),
        "resolution": ckpt["dataset"]["resolution"],
        "K": ckpt["model_args"]["K"],
        "scene": ckpt["dataset"]["scene"],
        "scene_hash": ckpt["dataset"]["scene_hash"],
        "dataset_hash": ckpt["dataset"]["hash"],
        "epoch": ckpt["epoch"],
        "step": ckpt["step"],
        "val": ckpt.get("val"),
        "model_args": dict(ckpt["model_args"]),
        "net_config": dict(ckpt["net_config"]),
        "config": dict(config),
        "versions": dict(ckpt.get("versions", {})),
    }
    return netG, encoding, meta


# ---------------------------------------------------------------------------------------------
# Validation, metrics.csv and curves.png


def validate(netG, val: np.ndarray, slices: Mapping[str, slice], enc: Encoding, cfg: TrainConfig, device,
             amp: bool) -> dict[str, float]:
    """Mean per-frame metrics of the composed image against the path-traced `pt`, netG in eval mode.

    Linear: MSE, PSNR (peak 1) and SSIM (data_range 1) on radiance as stored, as `diviewer.metrics`
    defines them. Tone-mapped (_tm): the same on `tonemap(x, enc.exposure)`. With target
    "indirect" the image is GL direct + predicted indirect, as the viewer composes it.
    """
    import torch

    from diviewer import metrics
    from diviewer.encoding import decode_radiance

    was_training = netG.training
    netG.eval()
    sums = dict.fromkeys(METRIC_KEYS, 0.0)
    with torch.no_grad():
        for start in range(0, len(val), cfg.batch_size):
            x16 = torch.from_numpy(val[start:start + cfg.batch_size]).to(device)
            b = split_batch(x16, slices, enc, cfg)
            with torch.autocast(device.type, dtype=torch.float16, enabled=amp):
                fake_B = netG(b["real_A"])
            pred = compose_radiance(decode_radiance(fake_B.float(), enc), b["direct"], b["albedo"], cfg.target,
                                    cfg.divide_albedo)
            pred = pred.permute(0, 2, 3, 1).cpu().numpy()
            truth = b["pt"].permute(0, 2, 3, 1).cpu().numpy()
            for p, t in zip(pred, truth):
                p_tm, t_tm = tonemap(p, enc.exposure), tonemap(t, enc.exposure)
                sums["mse"] += metrics.mse(p, t)
                sums["psnr"] += metrics.psnr(p, t)
                sums["ssim"] += metrics.ssim(p, t)
                sums["mse_tm"] += metrics.mse(p_tm, t_tm)
                sums["psnr_tm"] += metrics.psnr(p_tm, t_tm)
                sums["ssim_tm"] += metrics.ssim(p_tm, t_tm)
    netG.train(was_training)
    return {k: float(v / len(val)) for k, v in sums.items()}


def read_metrics(path: Path) -> list[dict[str, float | None]]:
    """metrics.csv rows as dicts of floats (None where a row has no value)."""
    if not path.is_file():
        return []
    with open(path, newline="") as f:
        return [{k: (float(v) if v not in ("", None) else None) for k, v in row.items()} for row in csv.DictReader(f)]


def _write_metrics(path: Path, rows: list[dict[str, Any]]) -> None:
    def cell(v: Any) -> str:
        return "" if v is None else (f"{v:.8g}" if isinstance(v, float) else str(v))

    lines = [",".join(CSV_COLUMNS)] + [",".join(cell(r.get(c)) for c in CSV_COLUMNS) for r in rows]
    imageio.write_text(path, "\n".join(lines) + "\n")


def draw_curves(rows: list[Mapping[str, Any]], path: Path) -> None:
    """curves.png: validation MSE and SSIM per epoch (linear and tone-mapped) and the train losses."""
    from PIL import Image, ImageDraw, ImageFont

    panels = [
        ("validation MSE (log)", [("linear", "val_mse"), ("tone-mapped", "val_mse_tm")], True),
        ("validation SSIM", [("linear", "val_ssim"), ("tone-mapped", "val_ssim_tm")], False),
        ("train losses (log)", [("D", "loss_D"), ("G GAN", "loss_G_GAN"), ("G L1", "loss_G_L1")], True),
    ]
    colors = [(31, 119, 180), (255, 127, 14), (44, 160, 44)]
    pw, ph, ml, mr, mt, mb = 420, 330, 64, 14, 42, 38
    img = Image.new("RGB", (pw * len(panels), ph), "white")
    draw = ImageDraw.Draw(img)
    font = ImageFont.load_default()
    for k, (title, series, log_y) in enumerate(panels):
        x0, x1, y0, y1 = k * pw + ml, (k + 1) * pw - mr, mt, ph - mb
        draw.text((k * pw + ml, 6), title, fill="black", font=font)
        draw.rectangle([x0, y0, x1, y1], outline="black")
        pts = {}
        for label, key in series:
            p = [(float(r["epoch"]), float(r[key])) for r in rows
                 if r.get(key) is not None and math.isfinite(float(r[key])) and (not log_y or float(r[key]) > 0)]
            pts[label] = [(x, math.log10(y) if log_y else y) for x, y in p]
        allp = [q for p in pts.values() for q in p]
        if not allp:
            draw.text((x0 + 10, (y0 + y1) // 2), "no data yet", fill="gray", font=font)
            continue
        xlo, xhi = min(q[0] for q in allp), max(q[0] for q in allp)
        ylo, yhi = min(q[1] for q in allp), max(q[1] for q in allp)
        if xhi - xlo < 1e-9:
            xlo, xhi = xlo - 0.5, xhi + 0.5
        pad = (yhi - ylo) * 0.05 or (0.5 if log_y else max(abs(ylo) * 0.05, 1e-3))
        ylo, yhi = ylo - pad, yhi + pad

        def to_px(x: float, y: float) -> tuple[float, float]:
            return (x0 + (x - xlo) / (xhi - xlo) * (x1 - x0), y1 - (y - ylo) / (yhi - ylo) * (y1 - y0))

        for i in range(5):
            fx = xlo + (xhi - xlo) * i / 4
            fy = ylo + (yhi - ylo) * i / 4
            px, _ = to_px(fx, ylo)
            _, py = to_px(xlo, fy)
            draw.line([px, y1, px, y1 + 4], fill="black")
            draw.text((px - 10, y1 + 6), f"{fx:.3g}", fill="black", font=font)
            draw.line([x0 - 4, py, x0, py], fill="black")
            draw.text((k * pw + 4, py - 6), f"{10 ** fy if log_y else fy:.3g}", fill="black", font=font)
        draw.text(((x0 + x1) // 2 - 14, ph - 14), "epoch", fill="black", font=font)
        lx = x0  # the legend: one row between the title and the plot
        for j, (label, p) in enumerate(pts.items()):
            color = colors[j % len(colors)]
            xy = [to_px(x, y) for x, y in p]
            if len(xy) > 1:
                draw.line(xy, fill=color, width=2)
            for px, py in xy:
                draw.ellipse([px - 2, py - 2, px + 2, py + 2], fill=color)
            draw.line([lx, 28, lx + 16, 28], fill=color, width=2)
            draw.text((lx + 20, 22), label, fill="black", font=font)
            lx += 20 + int(draw.textlength(label, font=font)) + 18
    with imageio.atomic_path(path) as tmp:
        img.save(tmp, format="PNG")


# ---------------------------------------------------------------------------------------------
# The training loop


def _install_stop_handlers(flag: dict[str, bool], log: Callable[[str], None]) -> Callable[[], None]:
    """First SIGINT/SIGTERM: finish the step, save last.ckpt, stop. A second SIGINT stops at once."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}

    def handler(signum, frame):
        if flag["stop"] and signum == signal.SIGINT:
            raise KeyboardInterrupt
        flag["stop"] = True
        log(f"\n{signal.Signals(signum).name}: stopping after this step and saving last.ckpt "
            "(Ctrl-C again to stop at once)")

    for s in old:
        signal.signal(s, handler)
    return lambda: [signal.signal(s, h) for s, h in old.items()]


def train(cfg: TrainConfig, resume: bool = False, log: Callable[[str], None] = print) -> dict[str, Any]:
    """Train netG and netD on cfg.data into cfg.out; see the module docstring.

    Args:
        cfg: the run's settings.
        resume: continue from cfg.out/last.ckpt exactly where it stopped (weights, optimizers,
            epoch, step within the epoch, random state, data order); a fresh run if there is none.
        log: where the per-epoch lines go (rank 0 only under torchrun).

    Returns:
        {"epoch", "step", "val" (last validation metrics or None), "best" (best tone-mapped SSIM),
        "losses" (per step run here: dicts with step, loss_D, loss_G_GAN, loss_G_L1), "out"}.
    """
    torch = _require_torch()
    import torch.distributed as dist
    from torch.nn.parallel import DistributedDataParallel as DDP

    from diviewer.data.dataset import Dataset
    from diviewer.encoding import Encoding
    from diviewer.console import progress_bar
    from diviewer.provenance import versions
    from diviewer.train.networks import GANLoss, NetConfig, init_weights, levels_for_resolution

    dev = _setup(cfg)
    out = cfg.out
    say = log if dev.main else (lambda *_: None)
    last_path, best_path = out / "last.ckpt", out / "best.ckpt"
    csv_path, png_path = out / "metrics.csv", out / "curves.png"
    try:
        # -- the data: train (and, on rank 0, val) split in RAM as stored (float16), checked --
        ds = Dataset(cfg.data)
        for name in ("depth", "normal", "albedo", "direct", "pt", "pt_direct"):
            if name not in ds.slices:
                raise DiviewerError(f"dataset has no '{name}' channel; training needs path-traced ground truth",
                                    path=ds.root)
        train_idx, train_arr = ds.array("train")
        val_arr = None
        if dev.main:
            if ds.indices("val"):
                val_arr = ds.array("val")[1]
            else:
                say(f"warning: {ds.root} has no val frames: no validation, no best.ckpt")

        # -- a fresh run, or the state of the interrupted one --
        ckpt = None
        if resume and last_path.is_file():
            ckpt = load_checkpoint(last_path)
            _check_resume(cfg, ckpt, ds, last_path)
        elif resume:
            say(f"no {last_path} yet: starting a new run")
        elif last_path.is_file():
            raise DiviewerError("already holds a run (last.ckpt); pass --resume to continue it or choose another --out",
                                path=out)
        enc = Encoding.from_dict(ckpt["encoding"]) if ckpt else fit_encoding(ds, train_idx, train_arr)

        try:
            levels = min(levels_for_resolution(ds.width), levels_for_resolution(ds.height))
        except ValueError:
            raise DiviewerError(f"resolution {ds.width}x{ds.height} must be even on both sides to train a U-Net",
                                path=ds.root) from None
        net_cfg = NetConfig(K=cfg.K, levels=levels, resolution=min(ds.width, ds.height), dropout=cfg.dropout,
                            ndf=cfg.ndf, lambda_L1=cfg.lambda_L1, target=cfg.target)

        # -- networks and optimizers (pix2pix: normal init, Adam(2e-4, (0.5, 0.999)) for each) --
        _seed_all(cfg.seed)
        netG = init_weights(net_cfg.build_generator()).to(dev.device)
        netD = init_weights(net_cfg.build_discriminator()).to(dev.device)
        optG = torch.optim.Adam(netG.parameters(), lr=cfg.lr, betas=(cfg.beta1, cfg.beta2))
        optD = torch.optim.Adam(netD.parameters(), lr=cfg.lr, betas=(cfg.beta1, cfg.beta2))
        amp = cfg.amp and dev.device.type == "cuda"
        if cfg.amp and not amp:
            say("note: --amp applies to CUDA only; training in float32 on the CPU")
        scaler = torch.amp.GradScaler("cuda", enabled=amp)
        criterionGAN = GANLoss().to(dev.device)
        criterionL1 = torch.nn.L1Loss()
        # Dropout draws differ per rank (after identical weights); ranks' states are all saved.
        _seed_all(cfg.seed + 1_000_003 * (dev.rank + 1))

        epoch, step, batch_in_epoch, elapsed = 0, 0, 0, 0.0
        accum = {"loss_D": 0.0, "loss_G_GAN": 0.0, "loss_G_L1": 0.0, "n": 0}
        best = {"ssim_tm": -math.inf, "epoch": None, "step": None}
        last_val = None
        if ckpt:
            netG.load_state_dict(ckpt["netG"])
            netD.load_state_dict(ckpt["netD"])
            optG.load_state_dict(ckpt["optG"])
            optD.load_state_dict(ckpt["optD"])
            if amp and ckpt.get("scaler"):
                scaler.load_state_dict(ckpt["scaler"])
            order = ckpt["data_order"]
            epoch, step, batch_in_epoch = order["epoch"], ckpt["step"], order["batch"]
            elapsed, accum, best, last_val = ckpt["elapsed"], dict(ckpt["accum"]), dict(ckpt["best"]), ckpt.get("val")
            best["ssim_tm"] = -math.inf if best["ssim_tm"] is None else best["ssim_tm"]
            rngs = ckpt["rng"]
            if order["world"] == dev.world and len(rngs) == dev.world:
                _set_rng_state(rngs[dev.rank], dev.device)
            else:
                say(f"warning: resuming with {dev.world} process(es) where the checkpoint had {order['world']}: "
                    "training continues, but not in exactly the order the interrupted run would have")
                _seed_all(cfg.seed + 1_000_003 * (dev.rank + 1) + step)
                batch_in_epoch = 0
            if dev.main:  # drop rows written after the checkpoint (a crash between the two)
                _write_metrics(csv_path, [r for r in read_metrics(csv_path) if r["step"] <= step])
            say(f"resuming {out} at epoch {epoch} (+{batch_in_epoch} steps), step {step}")
        elif dev.main:
            out.mkdir(parents=True, exist_ok=True)
            _write_metrics(csv_path, [])
        netG_m, netD_m = netG, netD  # the modules themselves; DDP wrappers below sync gradients
        if dev.world > 1:
            ids = [dev.device.index] if dev.device.type == "cuda" else None
            netG, netD = DDP(netG, device_ids=ids), DDP(netD, device_ids=ids)

        meta = {
            "format": CHECKPOINT_FORMAT, "format_version": CHECKPOINT_VERSION,
            "model_args": netG_m.model_args(), "netD_args": netD_m.model_args(), "net_config": net_cfg.to_dict(),
            "encoding": enc.to_dict(), "albedo_floor": ALBEDO_FLOOR, "config": cfg.to_dict(),
            "dataset": {"path": str(ds.root), "hash": ds.hash, "scene": ds.manifest.get("scene"),
                        "scene_hash": ds.manifest.get("scene_hash"), "resolution": [ds.width, ds.height],
                        "train_frames": len(train_idx), "val_frames": 0 if val_arr is None else len(val_arr)},
            "versions": versions(),
        }

        def save(val: dict[str, float] | None, is_best: bool) -> None:
            """Write last.ckpt (and best.ckpt); collective under torchrun (gathers every rank's RNG)."""
            nonlocal elapsed
            elapsed = elapsed0 + time.perf_counter() - t_start
            rng = _rng_state(dev.device)
            rngs = [rng]
            if dev.world > 1:
                rngs = [None] * dev.world
                dist.all_gather_object(rngs, rng)
            if dev.main:
                ckpt_out = {
                    **meta, "epoch": epoch, "step": step, "val": val,
                    "best": {**best, "ssim_tm": None if best["ssim_tm"] == -math.inf else best["ssim_tm"]},
                    "elapsed": elapsed, "accum": dict(accum),
                    "data_order": {"seed": cfg.seed, "epoch": epoch, "batch": batch_in_epoch, "world": dev.world,
                                   "batch_size": cfg.batch_size},
                    # On the CPU: a GPU-trained checkpoint then loads anywhere, even without map_location.
                    **_to_cpu({"netG": netG_m.state_dict(), "netD": netD_m.state_dict(),
                               "optG": optG.state_dict(), "optD": optD.state_dict(), "rng": rngs}),
                    "scaler": scaler.state_dict() if amp else None,
                }
                _atomic_save(ckpt_out, last_path)
                if is_best:
                    with imageio.atomic_path(best_path) as tmp:
                        shutil.copyfile(last_path, tmp)

        def end_of_stretch(do_val: bool) -> dict[str, float] | None:
            """Validate (rank 0), append the metrics row, redraw the curves, save the checkpoints."""
            nonlocal last_val, elapsed
            elapsed = elapsed0 + time.perf_counter() - t_start
            val = None
            is_best = False
            if dev.main:
                if do_val and val_arr is not None:
                    val = validate(netG_m, val_arr, ds.slices, enc, cfg, dev.device, amp)
                    last_val = val
                    if val["ssim_tm"] > best["ssim_tm"]:
                        best.update(ssim_tm=val["ssim_tm"], epoch=epoch, step=step)
                        is_best = True
                n = max(accum["n"], 1)
                row = {"epoch": round(epoch + batch_in_epoch / steps_per_epoch, 4), "step": step,
                       **{k: accum[k] / n for k in ("loss_D", "loss_G_GAN", "loss_G_L1")},
                       **{f"val_{k}": (val or {}).get(k) for k in METRIC_KEYS}, "seconds": round(elapsed, 2)}
                rows = read_metrics(csv_path) + [row]
                _write_metrics(csv_path, rows)
                draw_curves(rows, png_path)
            save(val, is_best)
            if dev.world > 1:
                dist.barrier()
            return val

        steps_per_epoch = len(epoch_batches(len(train_arr), 0, cfg.seed, cfg.batch_size, dev.rank, dev.world))
        total = cfg.epochs * steps_per_epoch
        if cfg.max_steps is not None:
            total = min(total, cfg.max_steps)
        history: list[dict[str, float]] = []
        if step >= total or epoch >= cfg.epochs:
            say(f"{out}: already trained to step {step} (epoch {epoch}); nothing to do")
            return _result(epoch, step, last_val, best, history, out)
        say(f"train {ds.manifest.get('scene')} K={cfg.K} target={cfg.target}{' /albedo' if cfg.divide_albedo else ''}: "
            f"{len(train_idx)} train frames at {ds.width}x{ds.height}, {steps_per_epoch} steps/epoch, "
            f"{dev.world} process(es) on {dev.device}{' with AMP' if amp else ''}, "
            f"exposure {enc.exposure:.4g}, depth_scale {enc.depth_scale:.4g}")
        elapsed0, t_start = elapsed, time.perf_counter()
        progress = progress_bar(total - step, "train", "step") if dev.main else None
        stop = {"stop": False}
        restore_handlers = _install_stop_handlers(stop, say)
        netG.train()
        netD.train()
        try:
            while epoch < cfg.epochs and step < total:
                t_epoch = time.perf_counter()
                batches = epoch_batches(len(train_arr), epoch, cfg.seed, cfg.batch_size, dev.rank, dev.world)
                for x16 in _loader(train_arr, batches[batch_in_epoch:], cfg, dev):
                    b = split_batch(x16.to(dev.device, non_blocking=True), ds.slices, enc, cfg)
                    real_A, real_B = b["real_A"], b["real_B"]
                    with torch.autocast(dev.device.type, dtype=torch.float16, enabled=amp):
                        fake_B = netG(real_A)
                        # netD: real pairs vs generated pairs (fake_B detached: no gradient into netG)
                        for p in netD.parameters():
                            p.requires_grad_(True)
                        pred_fake = netD(torch.cat([real_A, fake_B.detach()], 1))
                        pred_real = netD(torch.cat([real_A, real_B], 1))
                        loss_D = 0.5 * (criterionGAN(pred_fake, False) + criterionGAN(pred_real, True))
                    optD.zero_grad(set_to_none=True)
                    scaler.scale(loss_D).backward()
                    scaler.step(optD)
                    with torch.autocast(dev.device.type, dtype=torch.float16, enabled=amp):
                        # netG: fool the updated netD, and stay close to the target in L1. The bare
                        # module: under DDP no gradient of netD is reduced in this pass.
                        for p in netD.parameters():
                            p.requires_grad_(False)
                        loss_G_GAN = criterionGAN(netD_m(torch.cat([real_A, fake_B], 1)), True)
                        loss_G_L1 = criterionL1(fake_B.float(), real_B) * cfg.lambda_L1
                        loss_G = loss_G_GAN + loss_G_L1
                    optG.zero_grad(set_to_none=True)
                    scaler.scale(loss_G).backward()
                    scaler.step(optG)
                    scaler.update()

                    losses = torch.stack([loss_D.detach(), loss_G_GAN.detach(), loss_G_L1.detach()])
                    lD, lGAN, lL1 = losses.float().tolist()  # one device sync per step
                    if not amp and not all(map(math.isfinite, (lD, lGAN, lL1))):
                        raise DiviewerError(f"training diverged at step {step + 1} (loss D {lD}, G {lGAN}, L1 {lL1}); "
                                            "--resume continues from last.ckpt; try a lower --lr", path=out)
                    step += 1
                    batch_in_epoch += 1
                    accum["loss_D"] += lD
                    accum["loss_G_GAN"] += lGAN
                    accum["loss_G_L1"] += lL1
                    accum["n"] += 1
                    history.append({"step": step, "loss_D": lD, "loss_G_GAN": lGAN, "loss_G_L1": lL1})
                    if progress:
                        progress.set_postfix_str(f"epoch {epoch + 1} D {lD:.3f} G {lGAN:.3f} L1 {lL1:.3f}", refresh=False)
                        progress.update()
                    if _stop_requested(stop, dev):
                        save(None, False)
                        say(f"stopped at epoch {epoch} + {batch_in_epoch} steps, step {step}; "
                            f"continue with: diviewer train --data {cfg.data} --out {out} --resume")
                        raise KeyboardInterrupt
                    if step >= total:
                        break
                    if cfg.save_every and step % cfg.save_every == 0:
                        save(None, False)
                if batch_in_epoch >= len(batches):
                    epoch += 1
                    batch_in_epoch = 0
                    due = epoch % cfg.val_every == 0 or epoch == cfg.epochs or step >= total
                    n = max(accum["n"], 1)
                    line = (f"epoch {epoch}/{cfg.epochs} step {step} | D {accum['loss_D'] / n:.4f} "
                            f"G {accum['loss_G_GAN'] / n:.4f} L1 {accum['loss_G_L1'] / n:.4f}")
                    val = end_of_stretch(due)
                    accum = {"loss_D": 0.0, "loss_G_GAN": 0.0, "loss_G_L1": 0.0, "n": 0}
                    if val:
                        line += (f" | val PSNR {val['psnr']:.2f} dB SSIM {val['ssim']:.4f}"
                                 f" (tone-mapped {val['psnr_tm']:.2f} dB {val['ssim_tm']:.4f})")
                    say(f"{line} | {time.perf_counter() - t_epoch:.1f} s")
                else:  # stopped inside an epoch by max_steps: validate, record and save here
                    val = end_of_stretch(True)
                    say(f"stopped at max_steps {cfg.max_steps}: epoch {epoch} + {batch_in_epoch} steps"
                        + (f" | val SSIM {val['ssim']:.4f} (tone-mapped {val['ssim_tm']:.4f})" if val else ""))
                    break
        finally:
            restore_handlers()
            if progress:
                progress.close()
        return _result(epoch, step, last_val, best, history, out)
    finally:
        if dev.initialized_here and dist.is_initialized():
            dist.destroy_process_group()


def _to_cpu(obj: Any) -> Any:
    """Nested dicts/lists/tuples with every tensor moved to the CPU (state dicts keep their metadata)."""
    if callable(getattr(obj, "cpu", None)):
        return obj.cpu()
    if isinstance(obj, dict):
        out = type(obj)((k, _to_cpu(v)) for k, v in obj.items())
        if hasattr(obj, "_metadata"):
            out._metadata = obj._metadata
        return out
    if isinstance(obj, (list, tuple)):
        return type(obj)(_to_cpu(v) for v in obj)
    return obj


def _stop_requested(flag: dict[str, bool], dev: _Dist) -> bool:
    """Whether any process was asked to stop; every rank must agree, or the next collective hangs."""
    if dev.world == 1:
        return flag["stop"]
    import torch
    import torch.distributed as dist

    t = torch.tensor([1.0 if flag["stop"] else 0.0], device=dev.device)
    dist.all_reduce(t, op=dist.ReduceOp.MAX)
    return bool(t.item())


def _check_resume(cfg: TrainConfig, ckpt: Mapping[str, Any], ds: Dataset, path: Path) -> None:
    """The resumed run must train the same networks on the same data as the checkpoint's."""
    if ckpt["dataset"]["hash"] != ds.hash:
        raise DiviewerError(f"was trained on another dataset (hash {ckpt['dataset']['hash'][:12]}, "
                            f"{cfg.data} has {ds.hash[:12]}); resume with the same --data or choose another --out",
                            path=path)
    old = ckpt["config"]
    diff = [f"{k}: {old.get(k)!r} -> {getattr(cfg, k)!r}" for k in RESUME_FIXED if old.get(k) != getattr(cfg, k)]
    if diff:
        raise DiviewerError(f"cannot resume with different settings ({'; '.join(diff)}); "
                            "drop those options or choose another --out", path=path)


def _result(epoch, step, val, best, history, out) -> dict[str, Any]:
    return {"epoch": epoch, "step": step, "val": val,
            "best": None if best["ssim_tm"] == -math.inf else best["ssim_tm"], "losses": history, "out": out}


# ---------------------------------------------------------------------------------------------
# Command line


def add_train_parser(subparsers) -> argparse.ArgumentParser:
    """The `train` subcommand; it calls `run_train`. On --resume, options left out come from the
    checkpoint (see `RESUME_INHERITED`), and those that define the networks may not change."""
    d = {f.name: f.default for f in dataclasses.fields(TrainConfig)}
    p = subparsers.add_parser("train", help="train the neural GI network (cGAN) for one scene's dataset",
                              description="Train Deep Illumination's cGAN on a captured dataset; resumable.")
    p.add_argument("--data", type=Path, required=True, help="dataset folder (diviewer capture --out)")
    p.add_argument("--out", type=Path, required=True, help="run folder: checkpoints, metrics.csv, curves.png")
    p.add_argument("--resume", action="store_true", help="continue the run in --out exactly where it stopped")
    p.add_argument("--k", dest="K", type=int, default=None, help=f"generator base width (default {d['K']})")
    p.add_argument("--epochs", type=int, default=None, help=f"default {d['epochs']}")
    p.add_argument("--target", choices=("full", "indirect"), default=None,
                   help="predict the full GI image or indirect light only (default full)")
    p.add_argument("--divide-albedo", action="store_true", default=None,
                   help="with --target indirect: predict indirect / albedo")
    p.add_argument("--batch-size", type=int, default=None, help=f"default {d['batch_size']}")
    p.add_argument("--lr", type=float, default=None, help=f"Adam learning rate (default {d['lr']})")
    p.add_argument("--lambda-l1", dest="lambda_L1", type=float, default=None, help=f"default {d['lambda_L1']}")
    p.add_argument("--ndf", type=int, default=None, help=f"discriminator base width (default {d['ndf']})")
    p.add_argument("--seed", type=int, default=None, help=f"default {d['seed']}")
    p.add_argument("--max-steps", type=int, default=None, help="stop after this many steps in total")
    p.add_argument("--val-every", type=int, default=None, help="validate every N epochs (default 1)")
    p.add_argument("--save-every", type=int, default=None,
                   help="also save last.ckpt every N steps (default 0: epoch ends only)")
    p.add_argument("--amp", action="store_true", help="mixed precision (CUDA only)")
    p.add_argument("--num-workers", type=int, default=d["num_workers"], help="DataLoader workers (default 0)")
    p.add_argument("--device", default=d["device"], help="auto, cpu, cuda or cuda:N (default auto)")
    p.set_defaults(func=run_train)
    return p


def run_train(args: argparse.Namespace) -> int:
    """`diviewer train`: TrainConfig from the options (and, on --resume, the checkpoint's), then `train`."""
    _require_torch()
    given = {k: getattr(args, k, None) for k in RESUME_INHERITED}
    base: dict[str, Any] = {}
    last = Path(args.out) / "last.ckpt"
    if getattr(args, "resume", False) and last.is_file():
        old = load_checkpoint(last, mmap=True)["config"]
        base = {k: old[k] for k in RESUME_INHERITED if k in old}
    fields = {**base, **{k: v for k, v in given.items() if v is not None}}
    cfg = TrainConfig(data=args.data, out=args.out, max_steps=args.max_steps, amp=bool(args.amp),
                      num_workers=args.num_workers, device=args.device, **fields)
    result = train(cfg, resume=bool(getattr(args, "resume", False)))
    if result["best"] is not None:
        print(f"best tone-mapped SSIM {result['best']:.4f}; checkpoints in {cfg.out}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """`python -m diviewer.train.trainer` (e.g. under torchrun): the `train` subcommand on its own."""
    ap = argparse.ArgumentParser(prog="diviewer.train.trainer")
    add_train_parser(ap.add_subparsers(dest="command", required=True))
    args = ap.parse_args(["train", *(sys.argv[1:] if argv is None else argv)])
    try:
        return args.func(args)
    except DiviewerError as exc:
        print(f"diviewer train: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
