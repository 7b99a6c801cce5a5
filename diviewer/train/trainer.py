"""Train Deep Illumination's cGAN for one scene: pix2pix from G-buffers + direct light to the GI image.

Usage::

    diviewer train --data data/cornell --k 32 --epochs 50 --out runs/cornell_k32
    diviewer train --data data/cornell --out runs/cornell_k32 --resume      # continue exactly
    torchrun --standalone --nproc_per_node 4 -m diviewer.train.cli --data data/cornell --out runs/c4

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

This module is the loop; its rooms: settings `config.py`, what is learnt `targets.py`, processes
and random state `distributed.py`, checkpoints `checkpoint.py`, validation and curves `report.py`,
the command line `cli.py`.
"""

from __future__ import annotations

import math
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from diviewer import imageio
from diviewer.errors import DiviewerError
from diviewer.train import distributed
from diviewer.train.checkpoint import (CHECKPOINT_FORMAT, CHECKPOINT_VERSION, atomic_save, check_resume,
                                       load_checkpoint, require_torch, to_cpu)
from diviewer.train.config import TrainConfig
from diviewer.train.distributed import Dist, epoch_batches
from diviewer.train.report import METRIC_KEYS, draw_curves, read_metrics, validate, write_metrics
from diviewer.train.targets import ALBEDO_FLOOR, fit_encoding, split_batch

if TYPE_CHECKING:
    from diviewer.data.dataset import Dataset
    from diviewer.encoding import Encoding
    from diviewer.train.networks import NetConfig

CAPTURE_KEYS: tuple[str, ...] = ("frames", "spp", "max_depth", "seed", "split_fractions", "gt", "dtype")
"""Dataset manifest fields a checkpoint (and so a model card's recipe) records: how to capture it again."""

LOSS_KEYS: tuple[str, ...] = ("loss_D", "loss_G_GAN", "loss_G_L1")
"""The train losses summed per epoch and written as means to metrics.csv."""


def _empty_accum() -> dict[str, float]:
    return {**dict.fromkeys(LOSS_KEYS, 0.0), "n": 0}


@dataclass
class TrainState:
    """Where a run stands: what the loop advances and a checkpoint stores beside the weights."""

    epoch: int = 0
    """Finished epochs."""
    step: int = 0
    """Optimizer steps in total."""
    batch_in_epoch: int = 0
    """Steps done inside the unfinished epoch (where a resumed run continues the data order)."""
    elapsed: float = 0.0
    """Wall-clock seconds of all parts of the run, up to the last save or row."""
    accum: dict[str, float] = field(default_factory=_empty_accum)
    """Loss sums of the current epoch (and their count n); reset at each epoch end."""
    best: dict[str, Any] = field(default_factory=lambda: {"ssim_tm": -math.inf, "epoch": None, "step": None})
    """Best validation tone-mapped SSIM so far and where it was reached."""
    last_val: dict[str, float] | None = None
    """The latest validation metrics."""
    history: list[dict[str, float]] = field(default_factory=list)
    """Per-step losses of this invocation (returned to the caller)."""

    def add(self, losses: dict[str, float]) -> None:
        """Count one finished step."""
        self.step += 1
        self.batch_in_epoch += 1
        for k in LOSS_KEYS:
            self.accum[k] += losses[k]
        self.accum["n"] += 1
        self.history.append({"step": self.step, **losses})

    def means(self) -> dict[str, float]:
        """Mean train losses of the epoch so far."""
        n = max(self.accum["n"], 1)
        return {k: self.accum[k] / n for k in LOSS_KEYS}

    def to_checkpoint(self) -> dict[str, Any]:
        best = {**self.best, "ssim_tm": None if self.best["ssim_tm"] == -math.inf else self.best["ssim_tm"]}
        return {"epoch": self.epoch, "step": self.step, "val": self.last_val, "best": best,
                "elapsed": self.elapsed, "accum": dict(self.accum)}

    @classmethod
    def from_checkpoint(cls, ckpt: dict[str, Any]) -> TrainState:
        best = dict(ckpt["best"])
        best["ssim_tm"] = -math.inf if best["ssim_tm"] is None else best["ssim_tm"]
        return cls(epoch=ckpt["data_order"]["epoch"], step=ckpt["step"], batch_in_epoch=ckpt["data_order"]["batch"],
                   elapsed=ckpt["elapsed"], accum=dict(ckpt["accum"]), best=best, last_val=ckpt.get("val"))


@dataclass
class Nets:
    """The two networks (DDP-wrapped under torchrun; the bare modules as netG_m/netD_m), their
    optimizers, the gradient scaler and the losses."""

    netG: Any
    netD: Any
    netG_m: Any
    netD_m: Any
    optG: Any
    optD: Any
    scaler: Any
    amp: bool
    criterionGAN: Any
    criterionL1: Any


@dataclass
class Run:
    """What does not change while a run trains: settings, process, data, encoding, files."""

    cfg: TrainConfig
    dev: Dist
    ds: Dataset
    train_arr: np.ndarray
    val_arr: np.ndarray | None
    enc: Encoding
    meta: dict[str, Any]
    say: Callable[[str], None]
    t_start: float = field(default_factory=time.perf_counter)
    elapsed0: float = 0.0

    @property
    def out(self) -> Path:
        return self.cfg.out

    def elapsed(self) -> float:
        return self.elapsed0 + time.perf_counter() - self.t_start


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
    torch = require_torch()
    import torch.distributed as dist

    from diviewer.encoding import Encoding
    from diviewer.progress import Progress

    dev = distributed.setup(cfg)
    say = log if dev.main else (lambda *_: None)
    try:
        ds, train_idx, train_arr, val_arr = _load_splits(cfg, dev, say)
        ckpt = _open_run(cfg, ds, resume, say)
        enc = Encoding.from_dict(ckpt["encoding"]) if ckpt else fit_encoding(ds, train_idx, train_arr)
        net_cfg = _net_config(cfg, ds)
        _check_trainable(net_cfg, cfg, ds, len(train_idx))
        nets = _build_nets(cfg, net_cfg, dev, say)
        st = TrainState()
        if ckpt:
            st = _restore(nets, ckpt, cfg, dev, say)
        elif dev.main:
            cfg.out.mkdir(parents=True, exist_ok=True)
            write_metrics(cfg.out / "metrics.csv", [])
        if dev.world > 1:  # DDP wrappers all-reduce the gradients; the bare modules stay in nets.*_m
            ids = [dev.device.index] if dev.device.type == "cuda" else None
            nets.netG = torch.nn.parallel.DistributedDataParallel(nets.netG_m, device_ids=ids)
            nets.netD = torch.nn.parallel.DistributedDataParallel(nets.netD_m, device_ids=ids)
        run = Run(cfg=cfg, dev=dev, ds=ds, train_arr=train_arr, val_arr=val_arr, enc=enc, say=say,
                  meta=_checkpoint_meta(cfg, nets, net_cfg, enc, ds, train_idx, val_arr), elapsed0=st.elapsed)

        steps_per_epoch = len(epoch_batches(len(train_arr), 0, cfg.seed, cfg.batch_size, dev.rank, dev.world))
        total = cfg.epochs * steps_per_epoch
        if cfg.max_steps is not None:
            total = min(total, cfg.max_steps)
        if st.step >= total or st.epoch >= cfg.epochs:
            say(f"{cfg.out}: already trained to step {st.step} (epoch {st.epoch}); nothing to do")
            return _result(st, cfg.out)
        say(f"train {ds.manifest.get('scene')} K={cfg.K} target={cfg.target}{' /albedo' if cfg.divide_albedo else ''}: "
            f"{len(train_idx)} train frames at {ds.width}x{ds.height}, {steps_per_epoch} steps/epoch, "
            f"{dev.world} process(es) on {dev.device}{' with AMP' if nets.amp else ''}, "
            f"exposure {enc.exposure:.4g}, depth_scale {enc.depth_scale:.4g}")

        progress = Progress(total - st.step, label="train", unit="steps") if dev.main else None
        stop = {"stop": False}
        restore_handlers = distributed.install_stop_handlers(stop, say)
        nets.netG.train()
        nets.netD.train()
        try:
            while st.epoch < cfg.epochs and st.step < total:
                t_epoch = time.perf_counter()
                batches = epoch_batches(len(train_arr), st.epoch, cfg.seed, cfg.batch_size, dev.rank, dev.world)
                for x16 in distributed.loader(train_arr, batches[st.batch_in_epoch:], cfg, dev):
                    b = split_batch(x16.to(dev.device, non_blocking=True), ds.slices, enc, cfg)
                    losses = _train_step(nets, b, cfg)
                    if not nets.amp and not all(map(math.isfinite, losses.values())):
                        raise DiviewerError(f"training diverged at step {st.step + 1} ({_fmt(losses)}); "
                                            "--resume continues from last.ckpt; try a lower --lr", path=cfg.out)
                    st.add(losses)
                    if progress:
                        progress.update(extra=f"epoch {st.epoch + 1} {_fmt(losses)}")
                    if distributed.stop_requested(stop, dev):
                        _save(run, nets, st, None, False)
                        say(f"stopped at epoch {st.epoch} + {st.batch_in_epoch} steps, step {st.step}; "
                            f"continue with: diviewer train --data {cfg.data} --out {cfg.out} --resume")
                        raise KeyboardInterrupt
                    if st.step >= total:
                        break
                    if cfg.save_every and st.step % cfg.save_every == 0:
                        _save(run, nets, st, None, False)
                if st.batch_in_epoch >= len(batches):
                    st.epoch += 1
                    st.batch_in_epoch = 0
                    due = st.epoch % cfg.val_every == 0 or st.epoch == cfg.epochs or st.step >= total
                    line = f"epoch {st.epoch}/{cfg.epochs} step {st.step} | {_fmt(st.means())}"
                    val = _end_of_stretch(run, nets, st, due)
                    if val:
                        line += (f" | val PSNR {val['psnr']:.2f} dB SSIM {val['ssim']:.4f}"
                                 f" (tone-mapped {val['psnr_tm']:.2f} dB {val['ssim_tm']:.4f})")
                    say(f"{line} | {time.perf_counter() - t_epoch:.1f} s")
                else:  # stopped inside an epoch by max_steps: validate, record and save here
                    val = _end_of_stretch(run, nets, st, True)
                    say(f"stopped at max_steps {cfg.max_steps}: epoch {st.epoch} + {st.batch_in_epoch} steps"
                        + (f" | val SSIM {val['ssim']:.4f} (tone-mapped {val['ssim_tm']:.4f})" if val else ""))
                    break
        finally:
            restore_handlers()
        return _result(st, cfg.out)
    finally:
        if dev.initialized_here and dist.is_initialized():
            dist.destroy_process_group()


# ---------------------------------------------------------------------------------------------
# Before the loop: data, run folder, networks


def _load_splits(cfg: TrainConfig, dev: Dist, say) -> tuple[Dataset, list[int], np.ndarray, np.ndarray | None]:
    """The train split (and, on rank 0, val) in RAM as stored (float16), checked."""
    from diviewer.data.dataset import Dataset

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
    return ds, train_idx, train_arr, val_arr


def _open_run(cfg: TrainConfig, ds: Dataset, resume: bool, say) -> dict[str, Any] | None:
    """The checkpoint a resumed run continues (checked against the settings), or None for a new run."""
    last = cfg.out / "last.ckpt"
    if resume and last.is_file():
        ckpt = load_checkpoint(last)
        check_resume(cfg, ckpt, ds, last)
        return ckpt
    if last.is_file():
        raise DiviewerError("already holds a run (last.ckpt); pass --resume to continue it or choose another --out",
                            path=cfg.out)
    # Without last.ckpt there is nothing to resume, and a new run would replace these files.
    for name in ("best.ckpt", "metrics.csv", "curves.png"):
        path = cfg.out / name
        if path.is_file() and not (name == "metrics.csv" and not read_metrics(path)):
            raise DiviewerError("is left from an earlier run (no last.ckpt to resume); a new run would replace it: "
                                "move it away or choose another --out", path=path)
    if resume:
        say(f"no {last} yet: starting a new run")
    return None


def _net_config(cfg: TrainConfig, ds: Dataset) -> NetConfig:
    """The networks for this dataset's resolution and the run's settings."""
    from diviewer.train.networks import NetConfig, levels_for_resolution

    try:
        levels = min(levels_for_resolution(ds.width), levels_for_resolution(ds.height))
    except ValueError:
        raise DiviewerError(f"resolution {ds.width}x{ds.height} must be even on both sides to train a U-Net",
                            path=ds.root) from None
    return NetConfig(K=cfg.K, levels=levels, resolution=min(ds.width, ds.height), dropout=cfg.dropout,
                     ndf=cfg.ndf, lambda_L1=cfg.lambda_L1, target=cfg.target)


def _check_trainable(net_cfg: NetConfig, cfg: TrainConfig, ds: Dataset, n_train: int) -> None:
    """Refuse, before any file is written, a dataset these networks cannot train on.

    One forward pass of both networks on the "meta" device (shapes only: no memory, no weights,
    no random numbers drawn) in training mode, at the smallest batch the epoch will see: it fails
    exactly where training would, e.g. a PatchGAN kernel larger than its input (frames under
    3 * 2**n_layers_D px) or BatchNorm over a single value (a one-frame batch at a 1x1 map).
    """
    import torch

    smallest = n_train % cfg.batch_size or cfg.batch_size if n_train >= cfg.batch_size else n_train
    try:
        with torch.device("meta"):
            netG, netD = net_cfg.build_generator().train(), net_cfg.build_discriminator().train()
            real_A = torch.zeros(smallest, netG.in_channels, ds.height, ds.width)
            netD(torch.cat([real_A, netG(real_A)], 1))
    except (RuntimeError, ValueError) as exc:
        reason = str(exc).splitlines()[0]
        raise DiviewerError(f"cannot train on {n_train} frame(s) of {ds.width}x{ds.height} at batch size "
                            f"{cfg.batch_size}: {reason}; capture at least {3 * 2 ** net_cfg.n_layers_D} px per side "
                            "and more train frames", path=ds.root) from None


def _build_nets(cfg: TrainConfig, net_cfg: NetConfig, dev: Dist, say) -> Nets:
    """netG, netD and their optimizers (pix2pix: normal init, Adam(2e-4, (0.5, 0.999)) for each)."""
    import torch

    from diviewer.train.networks import GANLoss, init_weights

    distributed.seed_all(cfg.seed)
    netG = init_weights(net_cfg.build_generator()).to(dev.device)
    netD = init_weights(net_cfg.build_discriminator()).to(dev.device)
    optG = torch.optim.Adam(netG.parameters(), lr=cfg.lr, betas=(cfg.beta1, cfg.beta2))
    optD = torch.optim.Adam(netD.parameters(), lr=cfg.lr, betas=(cfg.beta1, cfg.beta2))
    amp = cfg.amp and dev.device.type == "cuda"
    if cfg.amp and not amp:
        say("note: --amp applies to CUDA only; training in float32 on the CPU")
    nets = Nets(netG=netG, netD=netD, netG_m=netG, netD_m=netD, optG=optG, optD=optD,
                scaler=torch.amp.GradScaler("cuda", enabled=amp), amp=amp,
                criterionGAN=GANLoss().to(dev.device), criterionL1=torch.nn.L1Loss())
    # Dropout draws differ per rank (after identical weights); ranks' states are all saved.
    distributed.seed_all(cfg.seed + 1_000_003 * (dev.rank + 1))
    return nets


def _restore(nets: Nets, ckpt: dict[str, Any], cfg: TrainConfig, dev: Dist, say) -> TrainState:
    """Weights, optimizers, random state and progress of the interrupted run."""
    nets.netG_m.load_state_dict(ckpt["netG"])
    nets.netD_m.load_state_dict(ckpt["netD"])
    nets.optG.load_state_dict(ckpt["optG"])
    nets.optD.load_state_dict(ckpt["optD"])
    if nets.amp and ckpt.get("scaler"):
        nets.scaler.load_state_dict(ckpt["scaler"])
    st = TrainState.from_checkpoint(ckpt)
    order, rngs = ckpt["data_order"], ckpt["rng"]
    if order["world"] == dev.world and len(rngs) == dev.world:
        distributed.set_rng_state(rngs[dev.rank], dev.device)
    else:
        say(f"warning: resuming with {dev.world} process(es) where the checkpoint had {order['world']}: "
            "training continues, but not in exactly the order the interrupted run would have")
        distributed.seed_all(cfg.seed + 1_000_003 * (dev.rank + 1) + st.step)
        st.batch_in_epoch = 0
    if dev.main:  # drop rows written after the checkpoint (a crash between the two)
        csv_path = cfg.out / "metrics.csv"
        write_metrics(csv_path, [r for r in read_metrics(csv_path) if r["step"] <= st.step])
    say(f"resuming {cfg.out} at epoch {st.epoch} (+{st.batch_in_epoch} steps), step {st.step}")
    return st


def _checkpoint_meta(cfg: TrainConfig, nets: Nets, net_cfg: NetConfig, enc: Encoding, ds: Dataset,
                     train_idx: list[int], val_arr: np.ndarray | None) -> dict[str, Any]:
    """What every checkpoint of this run records besides the weights and the progress."""
    from diviewer.provenance import versions

    return {
        "format": CHECKPOINT_FORMAT, "format_version": CHECKPOINT_VERSION,
        "model_args": nets.netG_m.model_args(), "netD_args": nets.netD_m.model_args(),
        "net_config": net_cfg.to_dict(), "encoding": enc.to_dict(), "albedo_floor": ALBEDO_FLOOR,
        "config": cfg.to_dict(),
        "dataset": {"path": str(ds.root), "hash": ds.hash, "scene": ds.manifest.get("scene"),
                    "scene_hash": ds.manifest.get("scene_hash"), "resolution": [ds.width, ds.height],
                    "train_frames": len(train_idx), "val_frames": 0 if val_arr is None else len(val_arr),
                    "capture": {k: ds.manifest.get(k) for k in CAPTURE_KEYS}},
        "versions": versions(),
    }


# ---------------------------------------------------------------------------------------------
# One step, and the end of a stretch (validation, metrics row, checkpoints)


def _train_step(nets: Nets, b: dict[str, Any], cfg: TrainConfig) -> dict[str, float]:
    """One pix2pix step: netD on real and generated pairs, then netG against the updated netD."""
    import torch

    real_A, real_B = b["real_A"], b["real_B"]
    device_type = real_A.device.type
    with torch.autocast(device_type, dtype=torch.float16, enabled=nets.amp):
        fake_B = nets.netG(real_A)
        # netD: real pairs vs generated pairs (fake_B detached: no gradient into netG)
        for p in nets.netD.parameters():
            p.requires_grad_(True)
        pred_fake = nets.netD(torch.cat([real_A, fake_B.detach()], 1))
        pred_real = nets.netD(torch.cat([real_A, real_B], 1))
        loss_D = 0.5 * (nets.criterionGAN(pred_fake, False) + nets.criterionGAN(pred_real, True))
    nets.optD.zero_grad(set_to_none=True)
    nets.scaler.scale(loss_D).backward()
    nets.scaler.step(nets.optD)
    with torch.autocast(device_type, dtype=torch.float16, enabled=nets.amp):
        # netG: fool the updated netD, and stay close to the target in L1. The bare module:
        # under DDP no gradient of netD is reduced in this pass.
        for p in nets.netD.parameters():
            p.requires_grad_(False)
        loss_G_GAN = nets.criterionGAN(nets.netD_m(torch.cat([real_A, fake_B], 1)), True)
        loss_G_L1 = nets.criterionL1(fake_B.float(), real_B) * cfg.lambda_L1
        loss_G = loss_G_GAN + loss_G_L1
    nets.optG.zero_grad(set_to_none=True)
    nets.scaler.scale(loss_G).backward()
    nets.scaler.step(nets.optG)
    nets.scaler.update()
    values = torch.stack([loss_D.detach(), loss_G_GAN.detach(), loss_G_L1.detach()]).float().tolist()
    return dict(zip(LOSS_KEYS, values))  # one device sync per step


def _save(run: Run, nets: Nets, st: TrainState, val: dict[str, float] | None, is_best: bool) -> None:
    """Write last.ckpt (and best.ckpt); collective under torchrun (gathers every rank's RNG)."""
    import torch.distributed as dist

    st.elapsed = run.elapsed()
    rng = distributed.rng_state(run.dev.device)
    rngs = [rng]
    if run.dev.world > 1:
        rngs = [None] * run.dev.world
        dist.all_gather_object(rngs, rng)
    if not run.dev.main:
        return
    cfg = run.cfg
    ckpt = {
        **run.meta, **st.to_checkpoint(), "val": val,
        "data_order": {"seed": cfg.seed, "epoch": st.epoch, "batch": st.batch_in_epoch, "world": run.dev.world,
                       "batch_size": cfg.batch_size},
        # On the CPU: a GPU-trained checkpoint then loads anywhere, even without map_location.
        **to_cpu({"netG": nets.netG_m.state_dict(), "netD": nets.netD_m.state_dict(),
                  "optG": nets.optG.state_dict(), "optD": nets.optD.state_dict(), "rng": rngs}),
        "scaler": nets.scaler.state_dict() if nets.amp else None,
    }
    atomic_save(ckpt, run.out / "last.ckpt")
    if is_best:
        with imageio.atomic_path(run.out / "best.ckpt") as tmp:
            shutil.copyfile(run.out / "last.ckpt", tmp)


def _end_of_stretch(run: Run, nets: Nets, st: TrainState, do_val: bool) -> dict[str, float] | None:
    """Validate (rank 0), append the metrics row, redraw the curves, save the checkpoints."""
    import torch.distributed as dist

    st.elapsed = run.elapsed()
    val = None
    is_best = False
    if run.dev.main:
        if do_val and run.val_arr is not None:
            val = validate(nets.netG_m, run.val_arr, run.ds.slices, run.enc, run.cfg, run.dev.device, nets.amp)
            st.last_val = val
            if val["ssim_tm"] > st.best["ssim_tm"]:
                st.best.update(ssim_tm=val["ssim_tm"], epoch=st.epoch, step=st.step)
                is_best = True
        steps_per_epoch = len(epoch_batches(len(run.train_arr), 0, run.cfg.seed, run.cfg.batch_size,
                                            run.dev.rank, run.dev.world))
        row = {"epoch": round(st.epoch + st.batch_in_epoch / steps_per_epoch, 4), "step": st.step,
               **st.means(), **{f"val_{k}": (val or {}).get(k) for k in METRIC_KEYS}, "seconds": round(st.elapsed, 2)}
        rows = read_metrics(run.out / "metrics.csv") + [row]
        write_metrics(run.out / "metrics.csv", rows)
        draw_curves(rows, run.out / "curves.png")
    if st.batch_in_epoch == 0:  # an epoch ended: its sums are written; the checkpoint starts the next
        st.accum = _empty_accum()
    _save(run, nets, st, val, is_best)
    if run.dev.world > 1:
        dist.barrier()
    return val


def _fmt(losses: dict[str, float]) -> str:
    return f"D {losses['loss_D']:.4f} G {losses['loss_G_GAN']:.4f} L1 {losses['loss_G_L1']:.4f}"


def _result(st: TrainState, out: Path) -> dict[str, Any]:
    return {"epoch": st.epoch, "step": st.step, "val": st.last_val,
            "best": None if st.best["ssim_tm"] == -math.inf else st.best["ssim_tm"], "losses": st.history, "out": out}


if __name__ == "__main__":  # the documented torchrun entry point before the command line moved to cli.py
    import sys

    from diviewer.train.cli import main

    sys.exit(main())
