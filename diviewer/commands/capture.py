"""`diviewer capture`: a dataset of GL inputs and ground truth."""

from __future__ import annotations

import argparse
import math

from diviewer.commands.common import add_number, add_out, add_scene, add_variant
from diviewer.errors import DiviewerError



def add_parser(sub) -> None:
    """`diviewer capture`: a dataset of GL inputs and ground truth."""
    p = sub.add_parser("capture", help="render a dataset: GL inputs and path-traced ground truth (resumable)")
    add_scene(p)
    add_number(p, "--frames", default=100, help="frames over all splits")
    p.add_argument("--res", default="128", help="N or WxH; default 128")
    p.add_argument("--gt", default="pt", choices=("pt", "vxgi"),
                   help="ground truth: pt (Mitsuba path tracer) or vxgi (voxel cone tracing, stored in the same channels)")
    add_number(p, "--vxgi-res", default=64, help="VXGI grid resolution with --gt vxgi (default 64)")
    add_number(p, "--spp", default=256, help="path-tracing samples per pixel (default 256)")
    add_number(p, "--max-depth", default=16, help="path length limit of the full render")
    add_number(p, "--seed", default=0, help="base seed of configurations and path-tracer seeds")
    p.add_argument("--splits", default="0.8,0.1,0.1", help="fractions train,val,test")
    p.add_argument("--dtype", default="float16", choices=("float16", "float32"), help="frame storage type")
    add_number(p, "--thumbs", default=2, help="PNG thumbnails per split")
    add_number(p, "--direct-samples", default=1, help="samples per axis of the stored direct light: 1 "
               "each pixel's centre (default), 4 the mean over its area (diviewer.gl.area)")
    p.add_argument("--shard", default=None, help="k/n: render every n-th frame starting at the k-th")
    add_variant(p)
    add_out(p, "dataset folder (created, or resumed)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Capture the dataset the options describe (resumable)."""
    from diviewer.data.capture import CaptureSettings, capture, parse_shard
    from diviewer.frames import parse_resolution

    width, height = parse_resolution(args.res)
    fractions = parse_splits(args.splits)
    settings = CaptureSettings(frames=args.frames, width=width, height=height, gt=args.gt, spp=args.spp,
                               max_depth=args.max_depth, seed=args.seed, split_fractions=fractions, dtype=args.dtype,
                               thumbs=args.thumbs, vxgi_resolution=args.vxgi_res, direct_samples=args.direct_samples)
    capture(args.scene, args.out, settings, parse_shard(args.shard))
    return 0


def parse_splits(text: str) -> tuple[float, float, float]:
    """``0.8,0.1,0.1``: three finite non-negative fractions train,val,test with a positive sum."""
    try:
        fractions = tuple(float(x) for x in str(text).split(","))
    except ValueError:
        fractions = ()
    if len(fractions) != 3 or not all(math.isfinite(f) and f >= 0 for f in fractions) or sum(fractions) <= 0:
        raise DiviewerError(f"takes three non-negative fractions train,val,test (e.g. 0.8,0.1,0.1), got '{text}'",
                            field="--splits")
    return fractions

