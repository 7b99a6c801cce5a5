"""Train Deep Illumination's cGAN for one scene: pix2pix from G-buffers + direct light to the GI image.

Usage::

    diviewer train --data data/cornell --k 32 --epochs 50 --out runs/cornell_k32
    diviewer train --data data/cornell --out runs/cornell_k32 --resume      # continue exactly
    torchrun --standalone --nproc_per_node 4 -m diviewer.train.cli --data data/cornell --out runs/c4

A run folder holds ``last.ckpt`` (every epoch, and wherever a run stops), ``best.ckpt`` (best
validation SSIM on tone-mapped images), ``metrics.csv`` (one row per epoch) and ``curves.png``.

Resume is exact (the same losses and weights as an uninterrupted run, bit for bit on one CPU): a checkpoint holds
both networks, both Adam states, the epoch and the step inside it, every process's random state (torch, CUDA, numpy,
python) and the loss sums of the unfinished epoch, and the data order is a pure function of (seed, epoch)
(`epoch_batches`). A first Ctrl-C or SIGTERM finishes the current step, saves last.ckpt and stops; `max_steps` stops
the same way, and so does early stopping (`patience` validations without a better tone-mapped SSIM).

No augmentation: a mirrored frame is a valid image only with the x component of the view-space normals negated,
and even then it shows a mirrored scene whose off-screen geometry (which bounces light into the frame) is on the
wrong side. The network learns one scene; flips would teach it two.

This module is the loop; its rooms: settings `config.py`, what is learnt `targets.py`, the networks `networks.py`,
the losses `losses.py`, one update of both networks `step.py`, processes and random state `distributed.py`,
checkpoints `checkpoint.py`, validation and curves `report.py`, the command line `cli.py`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from diviewer.errors import DiviewerError
from diviewer.train import distributed
from diviewer.train.checkpoint import (check_resume, init_record, load_checkpoint, open_parent, parent_encoding,
                                       require_torch, restore_run, run_metadata, save_run, warm_start)
from diviewer.train.config import TrainConfig
from diviewer.train.distributed import Dist, epoch_batches
from diviewer.train.report import METRIC_KEYS, draw_curves, read_metrics, validate, write_metrics
from diviewer.train.targets import (crop_plan, fit_encoding, raw_exposure, run_conditioning, run_light_scales,
                                    split_batch)

if TYPE_CHECKING:
    from diviewer.data.dataset import Dataset
    from diviewer.contract.encoding import Encoding
    from diviewer.train.networks import NetConfig
    from diviewer.train.step import Nets


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
    accum: dict[str, float] = field(default_factory=lambda: {"n": 0})
    """Sums of the step numbers (`step.STEP_KEYS`) over the current epoch, and their count n."""
    best: dict[str, Any] = field(default_factory=lambda: {"ssim_tm": -math.inf, "epoch": None, "step": None})
    """Best validation tone-mapped SSIM so far and where it was reached."""
    since_best: int = 0
    """Validations since the best one (early stopping stops at `patience`)."""
    last_val: dict[str, float] | None = None
    """The latest validation metrics."""
    history: list[dict[str, float]] = field(default_factory=list)
    """Per-step numbers of this invocation (returned to the caller)."""

    def add(self, numbers: dict[str, float]) -> None:
        """Count one finished step."""
        self.step += 1
        self.batch_in_epoch += 1
        for k, v in numbers.items():
            self.accum[k] = self.accum.get(k, 0.0) + v
        self.accum["n"] += 1
        self.history.append({"step": self.step, **numbers})

    def means(self) -> dict[str, float]:
        """Mean step numbers of the epoch so far."""
        n = max(self.accum["n"], 1)
        return {k: v / n for k, v in self.accum.items() if k != "n"}

    def new_epoch(self) -> None:
        self.epoch += 1
        self.batch_in_epoch = 0

    def to_checkpoint(self) -> dict[str, Any]:
        best = {**self.best, "ssim_tm": None if self.best["ssim_tm"] == -math.inf else self.best["ssim_tm"]}
        return {"epoch": self.epoch, "step": self.step, "val": self.last_val, "best": best,
                "elapsed": self.elapsed, "accum": dict(self.accum), "since_best": self.since_best}

    @classmethod
    def from_checkpoint(cls, ckpt: dict[str, Any], world: int) -> TrainState:
        best = dict(ckpt["best"])
        best["ssim_tm"] = -math.inf if best["ssim_tm"] is None else best["ssim_tm"]
        order = ckpt["data_order"]
        return cls(epoch=order["epoch"], step=ckpt["step"], elapsed=ckpt["elapsed"], accum=dict(ckpt["accum"]),
                   batch_in_epoch=order["batch"] if order["world"] == world else 0,  # another order: epoch start
                   best=best, since_best=ckpt.get("since_best", 0), last_val=ckpt.get("val"))


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
    steps_per_epoch: int
    multiple: int = 1
    """Frames are edge-padded to multiples of this (2**levels) before netG, as the runtime pads them."""
    train_scales: np.ndarray | None = None
    """Each train frame's light scale (encoding version 2), in train_arr's order."""
    val_scales: np.ndarray | None = None
    """Each val frame's light scale (encoding version 2), in val_arr's order."""
    train_cams: np.ndarray | None = None
    val_cams: np.ndarray | None = None
    """Each train / val frame's camera (encoding version 3, `targets.run_conditioning`), in the arrays' order."""
    train_lights: np.ndarray | None = None
    val_lights: np.ndarray | None = None
    """Each train / val frame's lights (encoding version 4, `targets.run_conditioning`), in the arrays' order."""
    tonemap_exposure: float | None = None
    """Validation's tone map: `fit_exposure` on the train frames' raw GL direct light, as `diviewer eval --data`
    fits it (with encoding 2 the encoding's exposure is the light-normalised data's); None: the encoding's."""
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
        "losses" (per step run here: dicts with step and `step.STEP_KEYS`), "out", "stopped_early"}.
    """
    require_torch()
    import torch.distributed as dist

    dev = distributed.setup(cfg)
    say = log if dev.main else (lambda *_: None)
    try:
        run, nets, st = _prepare(cfg, dev, say, resume)
        total = horizon = cfg.epochs * run.steps_per_epoch  # the lr schedule's horizon ignores max_steps
        if cfg.max_steps is not None:
            total = min(total, cfg.max_steps)
        if st.step >= total or st.epoch >= cfg.epochs or _patience_spent(cfg, st):
            say(f"{cfg.out}: already trained to step {st.step} (epoch {st.epoch}); nothing to do")
            return _result(cfg, st)
        ds, enc = run.ds, run.enc
        say(f"train {ds.manifest.get('scene')} K={cfg.K} target={cfg.target}{' /albedo' if cfg.divide_albedo else ''}: "
            f"{run.meta['dataset']['train_frames']} train frames at {ds.width}x{ds.height}, {run.steps_per_epoch} "
            f"steps/epoch, {dev.world} process(es) on {dev.device}{f' with {nets.dtype} autocast' if nets.dtype else ''}, "
            f"exposure {enc.exposure:.4g}{f' (output x {enc.output_gain:.4g})' if enc.output_gain != 1 else ''}, depth_scale {enc.depth_scale:.4g}, encoding {enc.version}"
            + (f", aspect crops {cfg.aspect_crops[0]:.3g}-{cfg.aspect_crops[1]:.3g}" if cfg.aspect_crops else ""))
        _epochs(run, nets, st, total, horizon)
        return _result(cfg, st)
    finally:
        if dev.initialized_here and dist.is_initialized():
            dist.destroy_process_group()


def _prepare(cfg: TrainConfig, dev: Dist, say, resume: bool) -> tuple[Run, Nets, TrainState]:
    """The run's data, encoding, networks and state: fresh, warm-started from a parent, or resumed."""
    import torch

    from diviewer.contract.encoding import Encoding
    from diviewer.train.networks import net_config
    from diviewer.train.step import build_nets

    ds, train_idx, train_arr, val_arr = _load_splits(cfg, dev, say)
    steps_per_epoch = len(epoch_batches(len(train_arr), 0, cfg.seed, cfg.batch_size, dev.rank, dev.world))
    if note := cfg.check_schedule(steps_per_epoch):
        say(note)
    ckpt = _open_run(cfg, ds, train_idx, resume, say)
    parent = open_parent(cfg, ds) if ckpt is None and cfg.init_from else None
    train_scales, val_scales = run_light_scales(cfg, ds, train_idx, val_arr is not None)
    if ckpt:
        enc = Encoding.from_dict(ckpt["encoding"])
    elif parent:  # the parent's weights were trained on its encoding: keep it
        enc = parent_encoding(parent, cfg)
    else:
        enc = fit_encoding(ds, train_idx, train_arr, train_scales, world=cfg.world_inputs, lights=cfg.light_inputs,
                           output_of=cfg, say=say)
    (train_cams, train_lights), (val_cams, val_lights) = run_conditioning(enc, ds, train_idx, val_arr is not None)
    net_cfg = net_config(cfg, ds)
    _check_trainable(net_cfg, cfg, ds, len(train_idx), enc.input_planes)
    nets = build_nets(cfg, net_cfg, enc, dev, say)
    st = TrainState()
    if parent:
        warm_start(nets, parent, cfg, say)
    if ckpt:
        restore_run(nets, ckpt, cfg, dev, say)
        st = TrainState.from_checkpoint(ckpt, dev.world)
        if dev.main:  # drop rows written after the checkpoint (a crash between the two)
            write_metrics(cfg.out / "metrics.csv", [r for r in read_metrics(cfg.out / "metrics.csv")
                                                    if r["step"] <= st.step])
        say(f"resuming {cfg.out} at epoch {st.epoch} (+{st.batch_in_epoch} steps), step {st.step}")
    elif dev.main:
        cfg.out.mkdir(parents=True, exist_ok=True)
        write_metrics(cfg.out / "metrics.csv", [])
    if dev.world > 1:  # DDP wrappers all-reduce the gradients; the bare modules stay in nets.*_m
        ids = [dev.device.index] if dev.device.type == "cuda" else None
        nets.netG = torch.nn.parallel.DistributedDataParallel(nets.netG_m, device_ids=ids)
        nets.netD = torch.nn.parallel.DistributedDataParallel(nets.netD_m, device_ids=ids)
    meta = run_metadata(cfg, nets, net_cfg, enc, ds, train_idx, 0 if val_arr is None else len(val_arr), ckpt)
    if parent or (ckpt and ckpt.get("init")):
        meta["init"] = init_record(parent) if parent else ckpt["init"]
    return Run(cfg=cfg, dev=dev, ds=ds, train_arr=train_arr, val_arr=val_arr, enc=enc, say=say,
               meta=meta, steps_per_epoch=steps_per_epoch, elapsed0=st.elapsed, multiple=2 ** net_cfg.levels,
               train_scales=train_scales, val_scales=val_scales, train_cams=train_cams, val_cams=val_cams,
               train_lights=train_lights, val_lights=val_lights,
               tonemap_exposure=None if enc.version < 2 else raw_exposure(ds, train_arr)), nets, st


def _epochs(run: Run, nets: Nets, st: TrainState, total: int, horizon: int) -> None:
    """The loop: steps to ``total`` (the learning rate's schedule runs to ``horizon``), validating, saving and
    stopping early as the settings say; a stop request saves last.ckpt and raises KeyboardInterrupt."""
    from diviewer.console import progress_bar
    from diviewer.train.step import set_learning_rate, train_step

    cfg, dev, train_arr, say = run.cfg, run.dev, run.train_arr, run.say
    progress = progress_bar(total, "train", "step", initial=st.step) if dev.main else None
    stop = {"stop": False}
    restore_handlers = distributed.install_stop_handlers(stop, say)
    nets.netG.train()
    nets.netD.train()
    try:
        while st.epoch < cfg.epochs and st.step < total and not _patience_spent(cfg, st):
            t_epoch = time.perf_counter()
            batches = epoch_batches(len(train_arr), st.epoch, cfg.seed, cfg.batch_size, dev.rank, dev.world)
            todo = batches[st.batch_in_epoch:]
            for k, x16 in enumerate(distributed.loader(train_arr, todo, cfg, dev)):
                set_learning_rate(nets, cfg, st.step, horizon)
                numbers = train_step(nets, _batch(run, x16.to(dev.device, non_blocking=True), todo[k],
                                                  st.epoch, st.batch_in_epoch))
                if not nets.scaler.is_enabled() and not all(map(math.isfinite, numbers.values())):
                    raise DiviewerError(f"training diverged at step {st.step + 1} ({_fmt(numbers)}); "
                                        "--resume continues from last.ckpt; try a lower --lr", path=cfg.out)
                st.add(numbers)
                if progress:
                    progress.set_postfix_str(f"epoch {st.epoch + 1} {_fmt(numbers)}", refresh=False)
                    progress.update()
                if distributed.stop_requested(stop, dev):
                    save_run(run, nets, st, None, False)
                    say(f"stopped at epoch {st.epoch} + {st.batch_in_epoch} steps, step {st.step}; "
                        f"continue with: diviewer train --data {cfg.data} --out {cfg.out} --resume")
                    raise KeyboardInterrupt
                if st.step >= total or st.batch_in_epoch >= len(batches):
                    break
                if cfg.val_every_steps and st.step % cfg.val_every_steps == 0:
                    _end_of_stretch(run, nets, st, True)
                    if _patience_spent(cfg, st):
                        break
                elif cfg.save_every and st.step % cfg.save_every == 0:
                    save_run(run, nets, st, None, False)
            if st.batch_in_epoch >= len(batches):
                st.new_epoch()
                due = st.epoch % cfg.val_every == 0 or st.epoch == cfg.epochs or st.step >= total
                line = f"epoch {st.epoch}/{cfg.epochs} step {st.step} | {_fmt(st.means())}"
                val = _end_of_stretch(run, nets, st, due)
                say(f"{line}{_fmt_val(val)} | {time.perf_counter() - t_epoch:.1f} s")
            elif not _patience_spent(cfg, st):  # stopped inside an epoch by max_steps: validate, record, save
                val = _end_of_stretch(run, nets, st, True)
                say(f"stopped at max_steps {cfg.max_steps}: epoch {st.epoch} + {st.batch_in_epoch} steps"
                    + _fmt_val(val))
                break
        if _patience_spent(cfg, st):
            say(f"early stop at step {st.step}: no better validation SSIM (tone-mapped) in {cfg.patience} "
                f"validations; best {st.best['ssim_tm']:.4f} at step {st.best['step']} (best.ckpt)")
    finally:
        restore_handlers()
        if progress:
            progress.close()


# ---------------------------------------------------------------------------------------------
# Before the loop: data, run folder, networks


def _load_splits(cfg: TrainConfig, dev: Dist, say) -> tuple[Dataset, list[int], np.ndarray, np.ndarray | None]:
    """The train split (its first cfg.train_frames frames by index, if set) and, on rank 0, val, in
    RAM as stored (float16), checked."""
    from diviewer.data.dataset import Dataset

    ds = Dataset(cfg.data)
    for name in ("depth", "normal", "albedo", "direct", "pt", "pt_direct"):
        if name not in ds.slices:
            raise DiviewerError(f"dataset has no '{name}' channel; training needs path-traced ground truth",
                                path=ds.root)
    train_idx = sorted(ds.indices("train"))
    if cfg.train_frames is not None:
        if len(train_idx) < cfg.train_frames:
            raise DiviewerError(f"has only {len(train_idx)} train frames yet; --train-frames {cfg.train_frames} "
                                "needs that many (wait for the capture, or ask for fewer)", path=ds.root)
        train_idx = train_idx[:cfg.train_frames]
    _, train_arr = ds.array("train", train_idx)
    val_arr = None
    if dev.main:
        if ds.indices("val"):
            _, val_arr = ds.array("val", sorted(ds.indices("val")))
        else:
            say(f"warning: {ds.root} has no val frames: no validation, no best.ckpt")
    return ds, train_idx, train_arr, val_arr


def _batch(run: Run, x16, indices: list[int], epoch: int, batch: int) -> dict[str, Any]:
    """One training batch for `train_step`: its aspect crop, light scales and padding, and validation's tone map."""
    import torch

    cfg, ds = run.cfg, run.ds
    plan = crop_plan(cfg, epoch, batch, x16.shape[0], ds.height, ds.width)
    pick = lambda a: None if a is None else torch.from_numpy(a[indices])  # noqa: E731
    b = split_batch(x16, ds.slices, run.enc, cfg, scale=pick(run.train_scales), multiple=run.multiple, crop=plan,
                    cams=pick(run.train_cams), lights=pick(run.train_lights))
    return {**b, "tonemap_exposure": run.enc.exposure if run.tonemap_exposure is None else run.tonemap_exposure}


def _open_run(cfg: TrainConfig, ds: Dataset, train_idx: list[int], resume: bool, say) -> dict[str, Any] | None:
    """The checkpoint a resumed run continues (checked against the settings), or None for a new run."""
    last = cfg.out / "last.ckpt"
    if resume and last.is_file():
        ckpt = load_checkpoint(last)
        check_resume(cfg, ckpt, ds, train_idx, last)
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


def _check_trainable(net_cfg: NetConfig, cfg: TrainConfig, ds: Dataset, n_train: int, channels: int) -> None:
    """Refuse, before any file is written, a dataset these networks cannot train on.

    One forward pass of both networks on the "meta" device (shapes only: no memory, weights or random numbers) in
    training mode, at the smallest batch the epoch will see: it fails exactly where training would, e.g. a PatchGAN
    kernel larger than its input (frames under 3 * 2**n_layers_D px) or a norm over one value (a one-frame batch at
    a 1x1 map). ``channels``: the encoding's input planes."""
    import torch

    smallest = (n_train % cfg.batch_size or cfg.batch_size) if n_train >= cfg.batch_size else n_train
    try:
        with torch.device("meta"):
            netG, netD = net_cfg.build_generator(channels).train(), net_cfg.build_discriminator(channels).train()
            from diviewer.contract.padding import padded_size

            m = 2 ** net_cfg.levels
            real_A = torch.zeros(smallest, netG.in_channels, padded_size(ds.height, m), padded_size(ds.width, m))
            netD(torch.cat([real_A, netG(real_A)], 1))
    except (RuntimeError, ValueError) as exc:
        reason = (str(exc).splitlines() or [type(exc).__name__])[0]
        raise DiviewerError(f"cannot train on {n_train} frame(s) of {ds.width}x{ds.height} at batch size "
                            f"{cfg.batch_size}: {reason}; capture at least {3 * 2 ** net_cfg.n_layers_D} px per side "
                            "and more train frames", path=ds.root) from None


# ---------------------------------------------------------------------------------------------
# The end of a stretch: validation, metrics row, curves, checkpoints


def _end_of_stretch(run: Run, nets: Nets, st: TrainState, do_val: bool) -> dict[str, float] | None:
    """Validate (rank 0), append the metrics row, redraw the curves, save the checkpoints."""
    val = None
    is_best = False
    st.elapsed = run.elapsed()
    if run.dev.main:
        if do_val and run.val_arr is not None:
            val = validate(nets.netG_m, run.val_arr, run.ds.slices, run.enc, run.cfg, run.dev.device, nets.dtype,
                           scales=run.val_scales, multiple=run.multiple, tonemap_exposure=run.tonemap_exposure,
                           cams=run.val_cams, lights=run.val_lights)
            st.last_val = val
            st.since_best += 1
            if val["ssim_tm"] > st.best["ssim_tm"]:
                st.best.update(ssim_tm=val["ssim_tm"], epoch=st.epoch + st.batch_in_epoch / run.steps_per_epoch,
                               step=st.step)
                st.since_best = 0
                is_best = True
        row = {"epoch": round(st.epoch + st.batch_in_epoch / run.steps_per_epoch, 4), "step": st.step,
               **st.means(), **{f"val_{k}": (val or {}).get(k) for k in METRIC_KEYS}, "seconds": round(st.elapsed, 2)}
        rows = read_metrics(run.out / "metrics.csv") + [row]
        write_metrics(run.out / "metrics.csv", rows)
        stopped = st.since_best >= run.cfg.patience > 0
        draw_curves(rows, run.out / "curves.png", best_epoch=st.best["epoch"],
                    stop_epoch=row["epoch"] if stopped else None)
    # Early stopping is decided on rank 0 (which validates); every rank must stop at the same step.
    st.since_best = distributed.agree_max(st.since_best, run.dev)
    if st.batch_in_epoch == 0:  # an epoch ended: its sums are written; the checkpoint starts the next
        st.accum = {"n": 0}
    save_run(run, nets, st, val, is_best)
    return val


def _patience_spent(cfg: TrainConfig, st: TrainState) -> bool:
    return cfg.patience > 0 and st.since_best >= cfg.patience


def _fmt(numbers: dict[str, float]) -> str:
    names = {"loss_D": "D", "loss_G_GAN": "G", "loss_G_L1": "rec", "loss_G_SSIM": "ssim", "D_acc_real": "Dacc real",
             "D_acc_fake": "fake"}
    return " ".join(f"{names[k]} {v:.4f}" for k, v in numbers.items() if k in names)


def _fmt_val(val: dict[str, float] | None) -> str:
    return (f" | val PSNR {val['psnr']:.2f} dB SSIM {val['ssim']:.4f} (tone-mapped {val['psnr_tm']:.2f} dB "
            f"{val['ssim_tm']:.4f})") if val else ""


def _result(cfg: TrainConfig, st: TrainState) -> dict[str, Any]:
    return {"epoch": st.epoch, "step": st.step, "val": st.last_val,
            "best": None if st.best["ssim_tm"] == -math.inf else st.best["ssim_tm"], "losses": st.history,
            "out": cfg.out, "stopped_early": _patience_spent(cfg, st)}
