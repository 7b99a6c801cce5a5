"""`diviewer baseline`: the per-pixel linear-regression baseline as an ONNX model."""

from __future__ import annotations

import argparse
from pathlib import Path

from diviewer.commands.common import add_number, add_out, add_split



def add_parser(sub) -> None:
    """`diviewer baseline`: the linear-regression baseline as an ONNX model."""
    p = sub.add_parser("baseline", help="fit the per-pixel linear-regression baseline on a dataset; write it as "
                                        "an ONNX model that eval, bench and view run like any model")
    p.add_argument("--data", type=Path, required=True, help="a dataset (diviewer capture)")
    add_out(p, "model.onnx (a model card model.json beside it)")
    add_split(p, "train", "split to fit on (train)")
    add_number(p, "--max-frames", default=None, help="fit on the first N present frames only")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Fit the baseline on the dataset's split and write it as an ONNX model."""
    from diviewer.evaluation.baseline import build_baseline

    build_baseline(args.data, args.out, split=args.split, max_frames=args.max_frames)
    return 0

