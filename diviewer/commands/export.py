"""`diviewer export`: a checkpoint to a verified ONNX model and its card, or a model's metadata."""

from __future__ import annotations

import argparse
from pathlib import Path

from diviewer.commands.common import add_number, add_out
from diviewer.errors import DiviewerError



def add_parser(sub) -> None:
    """`diviewer export`: a checkpoint to a verified ONNX model and its card."""
    p = sub.add_parser("export", help="checkpoint to ONNX (encoding inside the graph), verified against PyTorch")
    p.add_argument("checkpoint", type=Path, nargs="?", help="RUN/best.ckpt")
    add_out(p, "model.onnx (a model card model.json is written beside it)", required=False)
    p.add_argument("--fp16", action="store_true", help="float16 weights and generator (encoding stays float32)")
    p.add_argument("--half-weights", action="store_true",
                   help="float32 generator with its weights stored as float16: half the file, cast back on load")
    p.add_argument("--int8-weights", action="store_true",
                   help="float32 generator with its inner convolutions' weights stored as int8 (a scale per output "
                        "channel), the rest as float16: a quarter of float32's file, cast back on load")
    p.add_argument("--layout", choices=("NHWC", "NCHW"), default="NHWC",
                   help="the graph's input layout: NHWC as the GL pack writes it (default), or NCHW")
    add_number(p, "--verify-frames", default=4, help="frames compared with PyTorch before writing")
    p.add_argument("--info", type=Path, metavar="MODEL", help="print a model's metadata and exit")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Export the checkpoint (verified against PyTorch), or print a model's metadata (--info)."""
    from diviewer.train.export import ExportSettings, export, info

    if args.info:
        print(info(args.info))
        return 0
    if args.checkpoint is None or args.out is None:
        raise DiviewerError("give a checkpoint and --out (or --info MODEL)", field="export")
    export(args.checkpoint, args.out, ExportSettings(fp16=args.fp16, half_weights=args.half_weights,
                                                     int8_weights=args.int8_weights,
                                                     verify_frames=args.verify_frames, layout=args.layout))
    return 0
