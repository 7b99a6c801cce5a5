"""The command line's numeric options, one rule per option name across subcommands, checked before any work.

Every option that takes a number, or numbers in a string (``--res 320x240``, ``--gi-res 1/4``, ``--splits
0.8,0.1,0.1``, ``--ladder 1,4,16``), has an entry in `OPTIONS` by its destination: a `diviewer.fieldspec` spec
(finite, within its range; the same spec as the settings field it fills where there is one), applied to each value
of a list. `check_options` refuses a value out of range in one line naming the option (exit 2). An option that
takes text but no number is listed in `TEXT_OPTIONS`; tests/test_options.py walks every subcommand's parser and
holds each of its options to one of the two (`diviewer.commands.common.add_number` refuses a number without
an entry when the parser is built), so an option added without a range fails there.

Options bounded by what a GL context can hold name the limit (`GL_LIMITS`): `check_options` compares them with
``gl_info`` (a context's ``ctx.info``) where the caller has one, else with what every OpenGL 4.3 core context
guarantees (`GL_GUARANTEED`); the static caps (`MAX_SIZE`) lie below those, and the commands that render check
their real context again (`diviewer.gl.context.check_render_size`).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from diviewer.commands.parser import arguments, chosen_parser
from diviewer.errors import DiviewerError
from diviewer.fieldspec import MAX_SIZE, Float, Int, Ints, Invalid
from diviewer.train.config import TRAIN_FIELDS
from diviewer.train.recipe_fields import K, MAX_DEPTH, MAX_LADDER_K, SEED, SPP, TRUTH_FILTER
from diviewer.viewer.models import MIN_GI_SHARE, gi_share
from diviewer.viewer.scale import MAX_SCALE


@dataclass(frozen=True)
class Size:
    """``N`` (square) or ``WxH``, each side from 1 to ``hi`` (an int from ``type=int`` too)."""

    hi: int = MAX_SIZE
    lo: int = 1

    def describe(self) -> str:
        return f"N or WxH with each side from {self.lo} to {self.hi}"

    def sides(self, v: Any) -> tuple[int, int]:
        if isinstance(v, int) and not isinstance(v, bool):
            parts = [v]
        else:
            try:
                parts = [int(p) for p in str(v).lower().split("x")]
            except ValueError:
                parts = []
        if len(parts) == 1:
            parts *= 2
        if len(parts) != 2 or not all(self.lo <= p <= self.hi for p in parts):
            raise Invalid(f"must be {self.describe()}")
        return parts[0], parts[1]

    def check(self, v: Any) -> Any:
        self.sides(v)
        return v


@dataclass(frozen=True)
class GIRes:
    """``model``, a fraction of the window from 1/16 to 1/1 (``1/4``) or a size ``WxH``."""

    size: Size = Size()

    def describe(self) -> str:
        return f"'model', a fraction of the window from 1/16 to 1 (1/2, 1/4) or WxH up to {self.size.hi}"

    def check(self, v: Any) -> Any:
        text = str(v).strip().lower()
        if text == "model":
            return v
        if "/" in text:
            ratio = gi_share(text)
            if not (math.isfinite(ratio) and MIN_GI_SHARE <= ratio <= 1):
                raise Invalid(f"must be {self.describe()}")
            return v
        try:
            self.size.sides(text)
        except Invalid:
            raise Invalid(f"must be {self.describe()}") from None
        return v


@dataclass(frozen=True)
class Numbers:
    """Numbers separated by ``sep`` in a string (``1,4,16``), each as ``item`` (a spec)."""

    item: Any
    count: int | None = None
    sep: str = ","

    def describe(self) -> str:
        if isinstance(self.item, Ints):
            return f"{self.item.describe()[len('a list of '):]}, separated by '{self.sep}'"
        n = f"{self.count} " if self.count else ""
        return f"{n}numbers separated by '{self.sep}', each {self.item.describe()}"

    def check(self, v: Any) -> Any:
        try:
            values = [int(x) if isinstance(self.item, (Int, Ints)) else float(x) for x in str(v).split(self.sep)]
        except ValueError:
            raise Invalid(f"must be {self.describe()}") from None
        if self.count is not None and len(values) != self.count:
            raise Invalid(f"must be {self.describe()}")
        try:
            if isinstance(self.item, Ints):
                self.item.check(values)
            else:
                for x in values:
                    self.item.check(x)
        except Invalid:
            raise Invalid(f"must be {self.describe()}") from None
        return v


@dataclass(frozen=True)
class Shard:
    """``k/n``: the k-th of n shards, 1 <= k <= n <= ``hi``."""

    hi: int = 1_000_000

    def describe(self) -> str:
        return f"k/n with 1 <= k <= n <= {self.hi}"

    def check(self, v: Any) -> Any:
        try:
            k, n = (int(x) for x in str(v).split("/"))
        except ValueError:
            k = n = 0
        if not 1 <= k <= n <= self.hi:
            raise Invalid(f"must be {self.describe()}")
        return v


@dataclass(frozen=True)
class FrameRange:
    """``A:B``: the frame indices A <= index < B, 0 <= A < B."""

    def describe(self) -> str:
        return "A:B with 0 <= A < B"

    def check(self, v: Any) -> Any:
        try:
            a, b = (int(x) for x in str(v).split(":"))
        except ValueError:
            a = b = -1
        if not 0 <= a < b:
            raise Invalid(f"must be {self.describe()}")
        return v


@dataclass(frozen=True)
class Crops:
    """`train --aspect-crops`: () for 'off', else two aspect ratios as `TrainConfig.aspect_crops` takes them."""

    def describe(self) -> str:
        return "LO:HI, two finite aspect ratios 0 < LO <= HI <= 100, or off"

    def check(self, v: Any) -> Any:
        if v == ():
            return v
        try:
            lo, hi = TRAIN_FIELDS["aspect_crops"].check(v)
        except (Invalid, TypeError, ValueError):
            raise Invalid(f"must be {self.describe()}") from None
        if not lo <= hi:
            raise Invalid(f"must be {self.describe()}")
        return v


@dataclass(frozen=True)
class EvalExposure:
    """`eval --exposure`: ``scene``, ``metered`` or a number of stops as ``stops`` takes it (render's --exposure)."""

    stops: Any

    def describe(self) -> str:
        return f"scene, metered or a number of stops ({self.stops.describe()})"

    def check(self, v: Any) -> Any:
        if str(v).strip().lower() in ("scene", "metered"):
            return v
        try:
            self.stops.check(float(v))
        except (Invalid, TypeError, ValueError):
            raise Invalid(f"must be {self.describe()}") from None
        return v


_T = TRAIN_FIELDS
_CORE = {
    "seed": SEED, "pt_seed": Int(0, 2**32 - 2), "frames": Int(1, 1_000_000), "spp": SPP, "max_depth": MAX_DEPTH,
    "thumbs": Int(0, 1000), "verify_frames": Int(1, 1000), "max_frames": Int(1, 10**8), "jobs": Int(1, 1024),
    "exposure": Float(-40.0, 40.0), "res": Size(), "size": Size(), "gi_res": GIRes(), "shard": Shard(),
    "splits": Numbers(Float(0.0, 1e6), count=3), "vxgi_res": Int(16, 256, power_of_two=True),
    "vxgi_trace_scale": Int(1, 16), "direct_samples": Int(1, 16), "samples": Int(1, 16),
}
_TRAIN = {name: _T[name].spec if hasattr(_T[name], "spec") else _T[name] for name in (
    "K", "epochs", "batch_size", "lr", "lr_decay_start", "lambda_L1", "ndf", "max_steps", "val_every", "save_every",
    "gan_weight", "ssim_weight", "n_layers_D", "d_lr", "train_frames", "patience", "world_frequencies",
    "val_every_steps", "num_workers")}
_VIEW = {"fps": Float(1e-3, 1000.0, lo_open=True), "fixed_step": Float(1e-6, 10.0), "cells": Int(4, 128),
         "tolerance": Float(0.0, 100.0), "target_fps": Float(0.0, 1000.0), "render_scale": Float(0.0, MAX_SCALE, lo_open=True),
         "scale_floor": Float(0.0, 1.0, lo_open=True), "scale_ceiling": Float(1.0, MAX_SCALE)}
_BENCH = {"warmup": Int(0, 10_000), "untrained_k": K, "gi_steps": Int(1, 16), "eval_frames": Int(1, 100_000),
          "pt_frames": Int(1, 10_000), "vxgi_grids": Int(16, 256, power_of_two=True),
          "render_scales": Float(0.0, MAX_SCALE, lo_open=True)}
_OTHERS = {"budget": Float(0.0, 100_000.0, lo_open=True), "ks": Int(1, MAX_LADDER_K), "frames_per_split": Int(1, 100_000),
           "ladder": Numbers(Ints(SPP, max_len=64, increasing=True)),
           "window_widths": Numbers(Ints(Int(16, MAX_SIZE), max_len=64, distinct=True)),
           "aspect_crops": Crops(), "frame_range": FrameRange(),
           "deadline": Float(0.0, 4102444800.0),  # a Unix time before 2100
           **TRUTH_FILTER}

OPTIONS: dict[str, Any] = {**_CORE, **_TRAIN, **_VIEW, **_BENCH, **_OTHERS}
"""Each numeric option's spec, by its destination; the settings fields' own specs where the option fills one
(`train`'s options take `TrainConfig`'s, `data filter-truth`'s the recipe's ``truth_filter``'s)."""

COMMAND_OPTIONS: dict[tuple[str, str], Any] = {
    ("bench", "res"): Int(16, MAX_SIZE), ("evalset", "res"): Size(lo=16),
    ("eval", "exposure"): EvalExposure(_CORE["exposure"]),
}
"""Where one subcommand takes an option name otherwise: bench's square sizes, an evaluation set's >= 16 px
(SSIM's window is 11), eval's exposure mode (scene, metered, or stops as render's)."""

TEXT_OPTIONS: dict[str, str] = {
    "scene": "a shipped scene's name or a .toml path", "model": "a model file, auto or none",
    "recipe": "a shipped recipe's name or a .toml path", "device": "auto, cpu, cuda or cuda:N",
    "init_from": "a checkpoint", "stop_after": "a stage of the build's plan",
    "compare": "methods side by side: direct, neural, reference",
    "commands": "a command that made the model", "note": "a sentence on the model", "ladder_why": "why this K",
    "ladder_file": "a ladder record", "ladder_run": "a K and its training run", "method": "a row of eval's JSON",
    "key": "a model's key in eval's JSON",
}
"""Options that take text and no number (checked by the command that reads them)."""

GL_LIMITS: dict[str, tuple[str, ...]] = {
    "res": ("GL_MAX_TEXTURE_SIZE", "GL_MAX_RENDERBUFFER_SIZE"), "size": ("GL_MAX_TEXTURE_SIZE",
                                                                         "GL_MAX_RENDERBUFFER_SIZE"),
    "gi_res": ("GL_MAX_TEXTURE_SIZE",), "vxgi_res": ("GL_MAX_3D_TEXTURE_SIZE",),
    "vxgi_grids": ("GL_MAX_3D_TEXTURE_SIZE",),
}
"""Options a GL context bounds, and the limits (``ctx.info`` keys) that bound each side."""

GL_GUARANTEED: dict[str, int] = {"GL_MAX_TEXTURE_SIZE": 16384, "GL_MAX_RENDERBUFFER_SIZE": 16384,
                                 "GL_MAX_3D_TEXTURE_SIZE": 2048}
"""What every OpenGL 4.3 core context offers at least (the GL specification's minimum maximums)."""


def option_spec(command: str | None, dest: str) -> Any:
    """The spec of option ``dest`` of ``command``, or None where it takes no number."""
    return COMMAND_OPTIONS.get((command or "", dest), OPTIONS.get(dest))


def _sides(spec: Any, v: Any) -> tuple[int, ...]:
    """The pixel sides an option's value asks for (for the GL limits)."""
    if isinstance(spec, Size):
        return spec.sides(v)
    if isinstance(spec, GIRes) and "x" in str(v).lower():
        return spec.size.sides(str(v))
    return (v,) if isinstance(v, int) else ()


def check_options(ap: argparse.ArgumentParser, args: argparse.Namespace,
                  gl_info: Mapping[str, Any] | None = None) -> None:
    """Every numeric option of the chosen (sub)subcommand that was given: finite, in range, within the GL limits."""
    parser = chosen_parser(ap, args)
    limits = {**GL_GUARANTEED, **{k: v for k, v in (gl_info or {}).items() if isinstance(v, int)}}
    for action in arguments(parser):
        spec = option_spec(args.command, action.dest)
        value = getattr(args, action.dest, None)
        if spec is None or value is None or not action.option_strings:
            continue
        name = action.option_strings[0]
        for v in value if isinstance(value, list) else [value]:
            try:
                spec.check(v)
            except Invalid as exc:
                raise DiviewerError(f"{exc}, got {v}", field=name) from None
            for limit in GL_LIMITS.get(action.dest, ()):
                if any(side > limits[limit] for side in _sides(spec, v)):
                    raise DiviewerError(f"is larger than OpenGL allows ({limit} {limits[limit]}), got {v}", field=name)
