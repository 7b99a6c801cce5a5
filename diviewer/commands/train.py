"""`diviewer train`: a recipe (`--recipe`, default the best measured one), then options onto single `TrainConfig`
fields (on --resume, the checkpoint's settings fill what is not given), then `train`. `python -m diviewer.train.cli`
(e.g. under torchrun) runs the subcommand on its own (`main`)::

    torchrun --standalone --nproc_per_node 4 -m diviewer.train.cli --data data/cornell --out runs/c4
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import os
import sys
from pathlib import Path
from typing import Any

from diviewer.commands.common import add_number, add_out
from diviewer.commands.parser import CommandParser, arguments
from diviewer.errors import DiviewerError
from diviewer.locks import run_lock
from diviewer.outputs import check_output_dir
from diviewer.train.config import CHOICES, LEGACY_DEFAULTS, RESUME_INHERITED, TrainConfig
from diviewer.train.recipe import DEFAULT_RECIPE, load_recipe, shipped_recipes


def add_parser(subparsers) -> argparse.ArgumentParser:
    """The `train` subcommand; it calls `run`. A recipe gives every setting, options change single
    ones; the defaults shown are TrainConfig's (the paper's), which a recipe replaces. On --resume, options
    left out come from the checkpoint (see `RESUME_INHERITED`), and those that define the networks may not
    change."""
    d = {f.name: f.default for f in dataclasses.fields(TrainConfig)}
    p = subparsers.add_parser("train", help="train the neural GI network (cGAN) for one scene's dataset",
                              description="Train Deep Illumination's cGAN on a captured dataset with a recipe "
                                          "(assets/recipes/*.toml); options change single settings; resumable.")
    p.add_argument("--data", type=Path, required=True, help="dataset folder (diviewer capture --out)")
    add_out(p, "run folder: checkpoints, metrics.csv, curves.png")
    p.add_argument("--recipe", default=None, metavar="R",
                   help=f"a shipped recipe's name ({', '.join(shipped_recipes())}) or a .toml file; its [train] "
                        f"table gives every setting the options below do not (default {DEFAULT_RECIPE}: the best "
                        f"measured; on --resume, the checkpoint's settings)")
    p.add_argument("--resume", action="store_true", help="continue the run in --out exactly where it stopped")
    add_number(p, "--k", dest="K", default=None, help=f"generator base width (default {d['K']})")
    add_number(p, "--epochs", default=None, help=f"default {d['epochs']}")
    p.add_argument("--target", choices=("full", "indirect", "residual"), default=None,
                   help="predict the full GI image, indirect light only, or the path tracer minus the GL direct "
                        "light (residual) (default full)")
    p.add_argument("--divide-albedo", action="store_true", default=None,
                   help="with --target indirect or residual: predict it / albedo")
    add_number(p, "--batch-size", default=None, help=f"default {d['batch_size']}")
    add_number(p, "--lr", type=float, default=None, help=f"Adam learning rate (default {d['lr']})")
    p.add_argument("--lr-decay", choices=CHOICES["lr_decay"], default=None,
                   help="learning-rate schedule: none (default) or cosine (to lr/100 over all epochs)")
    p.add_argument("--init-from", default=None, metavar="CKPT",
                   help="start from this checkpoint's networks and encoding (RUN/best.ckpt of the same networks) "
                        "instead of random weights; optimizers, step and schedule start afresh")
    add_number(p, "--lr-decay-start", default=None, metavar="STEP",
               help="with --lr-decay cosine: constant rate up to STEP, then the decay (default 0); a run "
                    "at a constant rate resumes into an anneal that starts at or after its step")
    add_number(p, "--lambda-l1", dest="lambda_L1", type=float, default=None, help=f"default {d['lambda_L1']}")
    add_number(p, "--ndf", default=None, help=f"discriminator base width (default {d['ndf']})")
    add_number(p, "--seed", default=None, help=f"default {d['seed']}")
    add_number(p, "--max-steps", default=None, help="stop after this many steps in total")
    add_number(p, "--val-every", default=None, help="validate every N epochs (default 1)")
    add_number(p, "--save-every", default=None,
               help="also save last.ckpt every N steps (default 0: epoch ends only)")
    p.add_argument("--precision", choices=CHOICES["precision"], default=None,
                   help="autocast: auto (bf16 on CUDA, fp32 on the CPU; default), fp32, bf16, fp16 (CUDA only)")
    p.add_argument("--amp", action="store_true", help="the same as --precision fp16")
    _model_options(p, d)
    _data_options(p)
    add_number(p, "--num-workers", default=None, help="DataLoader workers (default 0)")
    p.add_argument("--device", default=None, help="auto, cpu, cuda or cuda:N (default auto)")
    _show_recipe_values(p, d)
    p.set_defaults(func=run)
    return p


def _show_recipe_values(p: argparse.ArgumentParser, d: dict) -> None:
    """Add to each option's help the value the default recipe gives it where that is not TrainConfig's default:
    a plain `diviewer train` runs the recipe, so `--help` should say what the run will take (K 8, not 32)."""
    try:
        given = load_recipe(DEFAULT_RECIPE).train
    except DiviewerError:  # a broken shipped recipe is reported when a run loads it, not by --help
        return
    for action in arguments(p):
        if action.dest in given and given[action.dest] != d.get(action.dest) and action.help:
            value = given[action.dest]
            shown = ":".join(f"{v:.4g}" for v in value) if isinstance(value, (list, tuple)) else value
            action.help += f" [the {DEFAULT_RECIPE} recipe: {shown}]"


def _model_options(p: argparse.ArgumentParser, d: dict) -> None:
    """`train`'s ablation options: the losses, the discriminator and the generator (``d``: TrainConfig's defaults)."""
    g = p.add_argument_group("losses and discriminator (ablations; defaults the paper's unless the recipe sets them)")
    add_number(g, "--gan-weight", type=float, default=None,
               help=f"weight of the adversarial term (default {d['gan_weight']}; 0: reconstruction only)")
    g.add_argument("--gan-mode", choices=CHOICES["gan_mode"], default=None, help="adversarial objective (default vanilla)")
    g.add_argument("--recon-loss", choices=CHOICES["recon_loss"], default=None, help="reconstruction norm (default l1)")
    g.add_argument("--recon-space", choices=CHOICES["recon_space"], default=None,
                   help="reconstruction on encoded values (default), linear radiance x exposure, its log, relative to the "
                        "prediction's brightness (l2 on linear or relative: unbiased, the mean of a noisy target), or "
                        "levels (4x4 block means and the detail around them: l1 near a noisy target's mean)")
    add_number(g, "--ssim-weight", type=float, default=None,
               help="weight of 1 - SSIM of the tone-mapped displayed frame beside the reconstruction term, both "
                    "times lambda_L1 (default 0: none; meant for a clean truth, docs/training.md)")
    g.add_argument("--ssim-exposure", choices=CHOICES["ssim_exposure"], default=None,
                   help="where that term tone-maps: the scene's exposure (default, as eval scores), each frame's "
                        "metered exposure (as the viewer shows it) or the mean of both")
    add_number(g, "--n-layers-d", dest="n_layers_D", default=None,
               help=f"discriminator stride layers (default {d['n_layers_D']}: 70x70 patches)")
    g.add_argument("--norm-d", dest="norm_D", choices=CHOICES["norm_D"], default=None,
                   help="discriminator normalisation (default batch)")
    add_number(g, "--d-lr", type=float, default=None, help="discriminator learning rate (default: --lr)")
    g = p.add_argument_group("generator (ablations; defaults the paper's unless the recipe sets them)")
    g.add_argument("--upsample", choices=CHOICES["upsample"], default=None, help="decoder upsampling (default transpose)")
    g.add_argument("--norm", choices=CHOICES["norm"], default=None, help="normalisation (default batch)")


def _data_options(p: argparse.ArgumentParser) -> None:
    """`train`'s options of the data, the encoding and stopping."""
    g = p.add_argument_group("data and stopping")
    add_number(g, "--train-frames", default=None,
               help="use only the first N train frames by index (default: all present)")
    add_number(g, "--patience", default=None,
               help="stop after N validations without a better tone-mapped SSIM (default 0: never)")
    g.add_argument("--light-scale", action=argparse.BooleanOptionalAction, default=None,
                   help="divide radiance by each frame's light scale: linear in the light, black without it "
                        "(encoding 2; default on; --no-light-scale: encoding 1)")
    g.add_argument("--world-inputs", action=argparse.BooleanOptionalAction, default=None,
                   help="also feed each pixel's world-space position and normal (encoding 3; default off)")
    g.add_argument("--light-inputs", action=argparse.BooleanOptionalAction, default=None,
                   help="also feed where each light is: a sun's direction, a point light's position (encoding 4; "
                        "needs --world-inputs; default off)")
    add_number(g, "--world-frequencies", default=None, metavar="L",
               help="Fourier features of the world position, sin and cos of pi 2^l p for l < L, into the "
                    "network's first layer (needs --world-inputs; default 0: the position as is)")
    g.add_argument("--output-gain", action=argparse.BooleanOptionalAction, default=None,
                   help="encode the target at its own exposure (its 99th percentile at 1), not the direct light's: "
                        "a sunlit scene's indirect light is a few %% of its direct light (default off)")
    g.add_argument("--aspect-crops", type=_aspect_range, default=None, metavar="LO:HI",
                   help="random-width crops per batch, width/height in LO..HI at full height, e.g. 0.5625:1.7778 "
                        "(9:16 to 16:9), or 'off' (default off)")
    add_number(g, "--val-every-steps", default=None,
               help="also validate (and save) every N steps (default 0: epoch ends only)")


def _aspect_range(text: str):
    """--aspect-crops LO:HI (or W/H fractions such as 9/16:16/9), or 'off'."""
    if text.strip().lower() in ("off", "none"):
        return ()
    try:
        lo, hi = (float(eval_fraction(v)) for v in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LO:HI (e.g. 0.5625:1.7778 or 9/16:16/9) or off, got {text!r}")
    return (lo, hi)


def eval_fraction(v: str) -> float:
    """'9/16' or '0.5625' as a float."""
    num, _, den = v.strip().partition("/")
    return float(num) / float(den) if den else float(num)


def run(args: argparse.Namespace) -> int:
    """`diviewer train`: TrainConfig from the options, then `train`."""
    from diviewer.train.checkpoint import load_checkpoint, require_torch
    from diviewer.train.trainer import train

    require_torch()
    check_output_dir(args.out, "--out", writes="run")  # also under torchrun, which bypasses diviewer.cli
    resume = bool(getattr(args, "resume", False))
    last = Path(args.out) / "last.ckpt"
    # a checkpoint from before a setting existed trained with its legacy value (LEGACY_DEFAULTS)
    old = {**LEGACY_DEFAULTS, **load_checkpoint(last, mmap=True)["config"]} if resume and last.is_file() else None
    cfg = resolve_config(args, old)
    if args.lr_decay_start is not None and cfg.lr_decay == "none":
        raise DiviewerError("sets where a decay starts, and this run has none; add --lr-decay cosine, or leave "
                            "--lr-decay-start out", field="--lr-decay-start")
    if cfg.recipe:
        changed = ", ".join(f"{k}={v}" for k, v in cfg.recipe.get("overrides", {}).items())
        print(f"recipe {cfg.recipe.get('name')} ({cfg.recipe.get('file')})"
              + (f"; changed: {changed}" if changed else ""))
    # One run per folder: a second train into --out refuses at once (under torchrun, rank 0 holds it).
    with run_lock(cfg.out, "train") if os.environ.get("RANK", "0") == "0" else contextlib.nullcontext():
        result = train(cfg, resume=resume)
    if result["best"] is not None:
        print(f"best tone-mapped SSIM {result['best']:.4f}; checkpoints in {cfg.out}")
    return 0


RUN_OPTIONS = ("max_steps", "precision", "num_workers", "device")
"""Options that describe this invocation on this machine: never inherited from a checkpoint on --resume."""


def resolve_config(args: argparse.Namespace, old: dict[str, Any] | None = None) -> TrainConfig:
    """The run's settings: the recipe's [train] table (on a resume, the checkpoint's `old` config instead unless
    --recipe is given again), then each option that was given. The recipe record names the fields the options
    changed."""
    given = {k: getattr(args, k, None) for k in (*RESUME_INHERITED, *RUN_OPTIONS) if k not in ("recipe",)}
    if getattr(args, "amp", False) and given["precision"] is None:
        given["precision"] = "fp16"
    given = {k: v for k, v in given.items() if v is not None}
    if given.get("aspect_crops") == ():  # --aspect-crops off
        given["aspect_crops"] = None
    name = getattr(args, "recipe", None)
    if old is not None and name is None:  # resumed: the checkpoint's settings and recipe record
        base = {k: old[k] for k in RESUME_INHERITED if k in old}
        return TrainConfig(data=args.data, out=args.out, recipe=old.get("recipe"), **{**base, **given})
    rec = load_recipe(name or DEFAULT_RECIPE)
    base = {k: old[k] for k in RESUME_INHERITED if k in old} if old is not None else {}
    fields = {**base, **rec.train, **given}
    overrides = {k: v for k, v in given.items() if k not in RUN_OPTIONS and rec.train.get(k, _DEFAULTS.get(k)) != v}
    try:
        return TrainConfig(data=args.data, out=args.out, recipe=rec.record(overrides), **fields)
    except DiviewerError as exc:
        where = "an option" if exc.field and exc.field.split(".")[-1] in given else f"recipe {rec.path}"
        raise DiviewerError(f"{exc} (from {where})") from None


_DEFAULTS = {f.name: f.default for f in dataclasses.fields(TrainConfig)}


def main(argv: list[str] | None = None) -> int:
    """`python -m diviewer.train.cli` (e.g. under torchrun): the `train` subcommand on its own."""
    ap = CommandParser(prog="diviewer.train.cli")
    add_parser(ap.add_subparsers(dest="command", required=True))
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
