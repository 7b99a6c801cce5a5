"""Checkpoints: written atomically, read with weights_only, self-describing enough to rebuild netG,
and the checks a resumed run must pass against the checkpoint it continues."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from diviewer import imageio
from diviewer.errors import DiviewerError, missing_extra
from diviewer.train.config import RESUME_FIXED, TrainConfig
from diviewer.train.targets import ALBEDO_FLOOR

if TYPE_CHECKING:
    from diviewer.data.dataset import Dataset

CHECKPOINT_FORMAT = "diviewer-checkpoint"
CHECKPOINT_VERSION = 1


def require_torch():
    """torch, or the user error that names the extra to install."""
    try:
        import torch
    except ImportError:
        raise missing_extra("torch") from None
    return torch


def atomic_save(obj: Any, path: Path) -> None:
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
    torch = require_torch()
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
        val metrics, model_args, net_config, train config, versions and the dataset's capture settings.
    """
    require_torch()
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
        "capture": ckpt["dataset"].get("capture"),
    }
    return netG, encoding, meta


# ---------------------------------------------------------------------------------------------
# Validation, metrics.csv and curves.png


def to_cpu(obj: Any) -> Any:
    """Nested dicts/lists/tuples with every tensor moved to the CPU (state dicts keep their metadata)."""
    if callable(getattr(obj, "cpu", None)):
        return obj.cpu()
    if isinstance(obj, dict):
        out = type(obj)((k, to_cpu(v)) for k, v in obj.items())
        if hasattr(obj, "_metadata"):
            out._metadata = obj._metadata
        return out
    if isinstance(obj, (list, tuple)):
        return type(obj)(to_cpu(v) for v in obj)
    return obj


def check_resume(cfg: TrainConfig, ckpt: Mapping[str, Any], ds: Dataset, path: Path) -> None:
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
