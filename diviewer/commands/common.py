"""The option builders every command module shares (scene, provider, model, split, outputs, numbers), so that
each option is written once with its type, help and choices.

A command module (`diviewer.commands.COMMANDS`) defines ``add_parser(subparsers)``, which adds its subcommand with
these builders, and ``run(args)``; its parsers are `diviewer.commands.parser.CommandParser`s, which record the
options added to them.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from diviewer.paths import scene_help

PROVIDERS = ("cpu", "cuda", "tensorrt")
"""The onnxruntime execution providers a command may ask for (`diviewer.contract.runtime` maps each to its provider)."""

SPLITS = ("train", "val", "test")
"""A dataset's splits."""


def add_scene(p, default: str | None = "cornell", help: str | None = None, **kwargs: Any) -> argparse.Action:
    """``--scene``: a shipped scene's name or a scene file (``help`` default: the shipped scenes listed)."""
    return p.add_argument("--scene", default=default, help=help or scene_help(), **kwargs)


def add_provider(p, help: str | None = None) -> argparse.Action:
    """``--provider``: the onnxruntime execution provider (default: the fastest available)."""
    return p.add_argument("--provider", default=None, choices=PROVIDERS, help=help)


def add_model(p, help: str, **kwargs: Any) -> argparse.Action:
    """``--model``: a model file (an ONNX model unless ``type`` says otherwise)."""
    kwargs.setdefault("type", Path)
    return p.add_argument("--model", help=help, **kwargs)


def add_split(p, default: str, help: str) -> argparse.Action:
    """``--split``: one of a dataset's splits."""
    return p.add_argument("--split", default=default, choices=SPLITS, help=help)


def add_out(p, help: str | None, required: bool = True, **kwargs: Any) -> argparse.Action:
    """``--out``: the command's output (a folder or a file, as ``help`` says); checked writable before any work."""
    if not required:
        kwargs.setdefault("default", None)
    return p.add_argument("--out", type=Path, required=required, help=help, **kwargs)


def add_json(p, help: str = "write the results as strict JSON") -> argparse.Action:
    """``--json FILE``: the results as JSON too."""
    return p.add_argument("--json", type=Path, default=None, help=help)


def add_number(p, *flags: str, type: type = int, **kwargs: Any) -> argparse.Action:
    """A numeric option: its range is the entry of `diviewer.options.OPTIONS` under its dest, checked before any
    work; an option without one is a mistake found when the parser is built."""
    from diviewer.options import OPTIONS

    action = p.add_argument(*flags, type=type, **kwargs)
    if action.dest not in OPTIONS:
        raise KeyError(f"{flags[0]} takes a number: give '{action.dest}' a range in diviewer.options.OPTIONS")
    return action


MITSUBA_VARIANTS = ("cuda_ad_rgb", "llvm_ad_rgb", "scalar_rgb")
"""--variant choices (diviewer.reference.variant.VARIANTS; not imported here to keep the parser light)."""


def add_variant(p) -> argparse.Action:
    """``--variant``: the Mitsuba variant of a command that path-traces."""
    return p.add_argument("--variant", default=None, choices=MITSUBA_VARIANTS,
                          help="Mitsuba variant (default: cuda_ad_rgb on a CUDA GPU, else llvm_ad_rgb where a libLLVM "
                               ">= 16 works, else scalar_rgb; a variant that cannot run here falls back the same way)")
