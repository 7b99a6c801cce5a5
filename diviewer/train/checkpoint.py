"""Checkpoints: written atomically, read with weights_only, self-describing enough to rebuild netG,
and the checks a resumed run must pass against the checkpoint it continues."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from diviewer import imageio
from diviewer.data.area import direct_samples
from diviewer.errors import DiviewerError, missing_extra
from diviewer.train.config import LEGACY_DEFAULTS, RESUME_FIXED, TrainConfig
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
        raise DiviewerError(f"not a readable checkpoint ({type(exc).__name__}: {(str(exc).splitlines() or [''])[0][:200]}); "
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
    from diviewer.contract.encoding import Encoding
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
        # samples per axis of the direct light the model was trained on (`diviewer data area-direct`); 1 before it existed
        "direct_samples": int(ckpt["dataset"].get("direct_samples", 1)),
        "epoch": ckpt["epoch"],
        "step": ckpt["step"],
        "val": ckpt.get("val"),
        "model_args": dict(ckpt["model_args"]),
        "net_config": dict(ckpt["net_config"]),
        "config": dict(config),
        "versions": dict(ckpt.get("versions", {})),
        "capture": capture_record(ckpt["dataset"]),
        "truth_spp": ckpt["dataset"].get("truth_spp"),
        "loss_config": ckpt.get("loss_config"),
        "init": ckpt.get("init"),
        "trained_on": trained_on_from_config(ckpt),
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


def changed_settings(cfg: TrainConfig, ckpt: Mapping[str, Any]) -> list[str]:
    """The settings a run resumed from ``ckpt`` with ``cfg`` may not change (`RESUME_FIXED`) but does, as
    "name: old -> new"; empty when it may resume."""
    old = ckpt["config"]
    # Settings a checkpoint from before they existed does not record had their default then.
    default = {**{f.name: f.default for f in dataclasses.fields(TrainConfig)}, **LEGACY_DEFAULTS}
    # The schedule may change only where it leaves the steps already taken as they were: a run at a
    # constant rate resumed into an anneal that starts at or after its step (see lr_decay_start).
    from diviewer.train.step import constant_until

    same_past = constant_until(old, ckpt["step"]) and constant_until(cfg, ckpt["step"])
    fixed = [k for k in RESUME_FIXED if not (same_past and k in ("lr_decay", "lr_decay_start"))]
    return [f"{k}: {old.get(k, default[k])!r} -> {getattr(cfg, k)!r}" for k in fixed
              if old.get(k, default[k]) != getattr(cfg, k)]


def check_resume(cfg: TrainConfig, ckpt: Mapping[str, Any], ds: Dataset, train_idx: list[int], path: Path) -> None:
    """The resumed run must train the same networks on the same data as the checkpoint's."""
    if ckpt["dataset"]["hash"] != ds.hash:
        raise DiviewerError(f"was trained on another dataset (hash {ckpt['dataset']['hash'][:12]}, "
                            f"{cfg.data} has {ds.hash[:12]}); resume with the same --data or choose another --out",
                            path=path)
    diff = changed_settings(cfg, ckpt)
    if diff:
        raise DiviewerError(f"cannot resume with different settings ({'; '.join(diff)}); "
                            "drop those options or choose another --out", path=path)
    then = ckpt["dataset"].get("train_indices")
    if then is not None and list(then) != list(train_idx):
        raise DiviewerError(f"the train split changed since this run began ({len(then)} frames then, "
                            f"{len(train_idx)} now; a capture still running?): resume with --train-frames {len(then)}",
                            path=path)


# ---------------------------------------------------------------------------------------------
# A run's checkpoints: what they record, writing them, and continuing from one


CAPTURE_KEYS: tuple[str, ...] = ("frames", "spp", "max_depth", "seed", "split_fractions", "gt", "dtype")
"""Dataset manifest fields a checkpoint (and so a model card's recipe) records: how to capture it again."""


def capture_record(dataset: Mapping[str, Any]) -> dict[str, Any] | None:
    """A checkpoint's dataset record as `diviewer capture` settings (a card's ``recipe.capture``): the manifest's
    CAPTURE_KEYS, ``direct_samples`` where the direct light covers each pixel's area (captured so, or derived by
    `diviewer data area-direct`: the same frames, tested), ``refine_from`` where the truth was refined from a
    capture at fewer samples (`diviewer data refine`) and ``truth_filter`` where its indirect light was filtered
    (`diviewer data filter-truth`), so that a recipe's [capture] table reads back alike."""
    cap = dataset.get("capture")
    if cap is None:
        return None
    n = int(dataset.get("direct_samples", 1))
    low, filt = dataset.get("refined_from_spp"), dataset.get("truth_filter")
    return {**cap, **({"direct_samples": n} if n != 1 else {}), **({"refine_from": low} if low is not None else {}),
            **({"truth_filter": dict(filt)} if filt else {})}


def captured_spp(manifest: Mapping[str, Any]) -> int:
    """The spp a refined dataset was first captured at (the innermost of its ``refined`` records)."""
    rec = manifest["refined"]
    while "before" in rec:
        rec = rec["before"]
    return int(rec["from_spp"])


def truth_spp(ds: Dataset, indices: list[int]) -> dict[str, int] | None:
    """The samples per pixel the truth of a refined dataset's frames really holds ({"min", "max"} over ``indices``):
    each frame's sidecar records its count before the last refinement and the samples added (the sampler rounds some
    counts up: Sponza's "256" frames hold 64 + 195). None for a dataset never refined (its manifest's ``spp``)."""
    import json

    if "refined" not in ds.manifest:
        return None
    counts = []
    for i in indices:
        rec = json.loads(ds.path(i, ".json").read_text())["refined"]
        counts.append(int(rec["from_spp"]) + int(rec["extra_spp"]))
    return {"min": min(counts), "max": max(counts)} if counts else None


def filter_settings(manifest: Mapping[str, Any]) -> dict[str, Any]:
    """The settings of a filtered truth (`diviewer data filter-truth`) as a recipe's [capture] truth_filter table."""
    from diviewer.data.truth_filter import FIELDS, TruthFilter

    return TruthFilter.from_dict({k: manifest["truth_filter"][k] for k in FIELDS if k in manifest["truth_filter"]},
                                 "truth_filter").record()


def run_metadata(cfg: TrainConfig, nets: Any, net_cfg: Any, enc: Any, ds: Dataset, train_idx: list[int],
                 n_val: int, resumed: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """What every checkpoint of a run records besides the weights and the progress (`resumed`: the
    checkpoint the run goes on from, whose hardware record is kept where this session's differs)."""
    from diviewer.provenance import versions

    return {
        "format": CHECKPOINT_FORMAT, "format_version": CHECKPOINT_VERSION,
        "model_args": nets.netG_m.model_args(), "netD_args": nets.netD_m.model_args(),
        "net_config": net_cfg.to_dict(), "loss_config": nets.loss.to_dict(), "encoding": enc.to_dict(),
        "albedo_floor": ALBEDO_FLOOR, "config": cfg.to_dict(),
        "dataset": {"path": str(ds.root), "hash": ds.hash, "scene": ds.manifest.get("scene"),
                    "scene_hash": ds.manifest.get("scene_hash"), "resolution": [ds.width, ds.height],
                    "train_frames": len(train_idx), "train_indices": list(train_idx), "val_frames": n_val,
                    "capture": {k: ds.manifest.get(k) for k in CAPTURE_KEYS},
                    "direct_samples": direct_samples(ds.manifest),
                    **({"refined_from_spp": captured_spp(ds.manifest), "truth_spp": truth_spp(ds, train_idx)}
                       if "refined" in ds.manifest else {}),
                    **({"truth_filter": filter_settings(ds.manifest)} if "truth_filter" in ds.manifest else {})},
        "versions": versions(),
        "trained_on": trained_on(nets, (resumed or {}).get("trained_on")),
    }


def trained_on(nets: Any, before: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Where the run trains: device kind and name, autocast precision, CPU threads; a model card says on
    what hardware its model was made. A run resumed on other hardware keeps the earlier record as
    ``before``."""
    import platform

    import torch

    dev = next(nets.netG_m.parameters()).device
    name = torch.cuda.get_device_name(dev) if dev.type == "cuda" else (platform.processor() or platform.machine())
    names = {None: "fp32", torch.bfloat16: "bf16", torch.float16: "fp16"}
    now = {"device": dev.type, "name": name, "autocast": names.get(nets.dtype, str(nets.dtype)),
           "torch_threads": torch.get_num_threads() if dev.type == "cpu" else None}
    if before and {k: v for k, v in before.items() if k != "before"} != now:
        now["before"] = dict(before)
    return now


def trained_on_from_config(ckpt: Mapping[str, Any]) -> dict[str, Any] | None:
    """`trained_on` of a checkpoint written before checkpoints recorded it: known only where the run
    named the CPU (``--device cpu``), which trains float32 unless bf16 was asked for; None otherwise."""
    if ckpt.get("trained_on"):
        return dict(ckpt["trained_on"])
    cfg = ckpt["config"]
    if cfg.get("device") != "cpu":
        return None
    return {"device": "cpu", "autocast": "bf16" if cfg.get("precision") == "bf16" else "fp32",
            "recorded": False}


def save_run(run: Any, nets: Any, st: Any, val: dict[str, float] | None, is_best: bool) -> None:
    """Write last.ckpt (and best.ckpt); collective under torchrun: gathers every rank's RNG, and no
    rank returns before the files are written (a rank that goes on to read them sees them whole)."""
    import torch.distributed as dist

    from diviewer.train.distributed import rng_state

    st.elapsed = run.elapsed()
    rng = rng_state(run.dev.device)
    rngs = [rng]
    if run.dev.world > 1:
        rngs = [None] * run.dev.world
        dist.all_gather_object(rngs, rng)
    if run.dev.main:
        _write_run_checkpoints(run, nets, st, val, is_best, rngs)
    if run.dev.world > 1:
        dist.barrier()


def _write_run_checkpoints(run: Any, nets: Any, st: Any, val: dict[str, float] | None, is_best: bool,
                           rngs: list[Any]) -> None:
    import shutil

    cfg = run.cfg
    ckpt = {
        **run.meta, **st.to_checkpoint(), "val": val,
        "data_order": {"seed": cfg.seed, "epoch": st.epoch, "batch": st.batch_in_epoch, "world": run.dev.world,
                       "batch_size": cfg.batch_size},
        # On the CPU: a GPU-trained checkpoint then loads anywhere, even without map_location.
        **to_cpu({"netG": nets.netG_m.state_dict(), "netD": nets.netD_m.state_dict(),
                  "optG": nets.optG.state_dict(), "optD": nets.optD.state_dict(), "rng": rngs}),
        "scaler": nets.scaler.state_dict() if nets.scaler.is_enabled() else None,
    }
    atomic_save(ckpt, cfg.out / "last.ckpt")
    if is_best:
        with imageio.atomic_path(cfg.out / "best.ckpt") as tmp:
            shutil.copyfile(cfg.out / "last.ckpt", tmp)


# ---------------------------------------------------------------------------------------------
# A warm start: a new run that begins from another run's networks (TrainConfig.init_from)


def open_parent(cfg: TrainConfig, ds: Dataset) -> dict[str, Any]:
    """The checkpoint ``cfg.init_from`` names, checked to be of this dataset's scene and of this run's
    target; its networks are compared with this run's in ``warm_start``."""
    path = Path(cfg.init_from)
    if not path.is_file():
        raise DiviewerError(f"no checkpoint at {path}", field="train.init_from")
    parent = load_checkpoint(path)
    then = parent["dataset"]
    if then.get("scene_hash") != ds.manifest.get("scene_hash"):
        raise DiviewerError(f"{path} was trained on scene '{then.get('scene')}' (another scene file than "
                            f"{cfg.data}'s '{ds.manifest.get('scene')}')", field="train.init_from")
    old = parent["config"]
    diff = [f"{k}: {old.get(k)!r} there, {getattr(cfg, k)!r} here" for k in ("target", "divide_albedo")
            if old.get(k) != getattr(cfg, k)]
    if diff:
        raise DiviewerError(f"{path} predicts something else ({'; '.join(diff)})", field="train.init_from")
    parent["path"] = str(path)
    return parent


def parent_encoding(parent: Mapping[str, Any], cfg: TrainConfig):
    """The encoding a warm start keeps (its weights were trained on it), refused where this run asks another."""
    from diviewer.contract.encoding import Encoding

    enc = Encoding.from_dict(parent["encoding"])
    if (enc.light_scaled, enc.world_inputs, enc.light_inputs) != (cfg.light_scale, cfg.world_inputs,
                                                                     cfg.light_inputs):
        flags = " ".join(f"--{'' if on else 'no-'}{name}" for on, name in ((enc.light_scaled, "light-scale"),
                                                                          (enc.world_inputs, "world-inputs"),
                                                                          (enc.light_inputs, "light-inputs")))
        raise DiviewerError(f"--init-from's model was trained with encoding {enc.version}; pass {flags} to "
                            "warm-start from it", path=cfg.init_from)
    return enc


def warm_start(nets: Any, parent: Mapping[str, Any], cfg: TrainConfig, say) -> None:
    """Load the parent's generator (and its discriminator where it is the same network) into ``nets``."""
    args, then = nets.netG_m.model_args(), parent["model_args"]
    diff = [f"{k}: {then.get(k)!r} there, {args.get(k)!r} here" for k in sorted(set(args) | set(then))
            if args.get(k) != then.get(k)]
    if diff:
        raise DiviewerError(f"{parent['path']} holds another generator ({'; '.join(diff)}): give this run the "
                            "same networks", field="train.init_from")
    nets.netG_m.load_state_dict(parent["netG"])
    if parent.get("netD_args") == nets.netD_m.model_args():
        nets.netD_m.load_state_dict(parent["netD"])
    else:
        say("the discriminator starts from random weights (the parent's is another network)")
    say(f"starting from {parent['path']} (step {parent['step']}, trained on "
        f"{parent['dataset']['train_frames']} frames of {parent['dataset']['path']})")


def init_record(parent: Mapping[str, Any]) -> dict[str, Any]:
    """What a warm-started run records of its parent: the file's hash and step, and how the parent was
    made (its settings, capture and networks, and its own parent's record), so that a model card's
    recipe can rebuild the chain."""
    from diviewer.data.dataset import sha256_file

    return {"path": parent["path"], "checkpoint_sha256": sha256_file(Path(parent["path"])), "step": parent["step"],
            "dataset_hash": parent["dataset"]["hash"], "train_frames": parent["dataset"]["train_frames"],
            "meta": {"config": parent["config"], "capture": capture_record(parent["dataset"]),
                     "net_config": parent["net_config"], "loss_config": parent.get("loss_config"),
                     **({"init": parent["init"]} if parent.get("init") else {})}}


def restore_run(nets: Any, ckpt: Mapping[str, Any], cfg: TrainConfig, dev: Any, say) -> None:
    """Weights, optimizers and random state of the interrupted run (its progress: `TrainState`)."""
    from diviewer.train.distributed import seed_all, set_rng_state

    nets.netG_m.load_state_dict(ckpt["netG"])
    nets.netD_m.load_state_dict(ckpt["netD"])
    nets.optG.load_state_dict(ckpt["optG"])
    nets.optD.load_state_dict(ckpt["optD"])
    if nets.scaler.is_enabled() and ckpt.get("scaler"):
        nets.scaler.load_state_dict(ckpt["scaler"])
    order, rngs = ckpt["data_order"], ckpt["rng"]
    if order["world"] == dev.world and len(rngs) == dev.world:
        set_rng_state(rngs[dev.rank], dev.device)
    else:
        say(f"warning: resuming with {dev.world} process(es) where the checkpoint had {order['world']}: "
            "training continues, but not in exactly the order the interrupted run would have")
        seed_all(cfg.seed + 1_000_003 * (dev.rank + 1) + ckpt["step"])
