"""`diviewer data check | merge | refine | refine-job | render-extras | area-direct | filter-truth`: a dataset's
actions, their options and what they run."""

from __future__ import annotations

import argparse
from pathlib import Path

from diviewer.commands.common import add_number, add_out
from diviewer.errors import DiviewerError
from diviewer.locks import run_lock


def _check(args: argparse.Namespace) -> int:
    from diviewer.data.capture import summarize
    from diviewer.data.dataset import Dataset, read_manifest

    if "compact" in read_manifest(args.dir):  # a compact evaluation set: one zip, checksums in its manifest
        from diviewer.evaluation.frames import EvalFrames

        ev = EvalFrames(args.dir)
        problems = ev.problems()
        for p in problems:
            print(f"frame {p.index:6d}: {p.problem}")
        print(f"{args.dir}: compact evaluation set of {ev.manifest['scene']}, {len(ev.frames)} frames: "
              + (f"{len(problems)} bad; write it again with `diviewer evalset --compact FULL_DIR --out {args.dir}`"
                 if problems else "all present and sound"))
        return 1 if problems else 0
    ds = Dataset(args.dir)
    problems = ds.check(verify_checksum=not args.fast)
    s = summarize(ds)
    print(f"{args.dir}: {ds.manifest['scene']} {ds.width}x{ds.height}, {s['present']}/{s['planned']} frames present "
          f"({', '.join(f'{k} {v}' for k, v in s['per_split'].items())}), {s['disk_mb']:.1f} MB")
    for p in problems:
        print(f"frame {p.index:6d}: {p.problem}")
    if problems:
        command = "evalset" if ds.manifest.get("kind") == "evalset" else "capture"  # whose folder this is
        print(f"{len(problems)} frame(s) missing or bad; run the same `diviewer {command}` again to render them")
        return 1
    print("all frames present and sound")
    return 0


def _merge(args: argparse.Namespace) -> int:
    from diviewer.data.capture import merge

    for src in args.sources:
        if src.exists() and args.out.exists() and src.resolve() == args.out.resolve():
            raise DiviewerError(f"{src} is both a source and the output", field="--out")

    with run_lock(args.out, "data merge"):  # the same lock as a capture into this folder
        merge(args.sources, args.out)
    return 0


def _refine(args: argparse.Namespace) -> int:
    from diviewer.data.capture import parse_shard
    from diviewer.data.refine import refine

    refine(args.dir, args.out, args.spp, parse_shard(args.shard), extras=args.extras, partial=args.partial)
    return 0


def _refine_job(args: argparse.Namespace) -> int:
    from diviewer.data.refine_extras import write_job

    first, stop = (int(x) for x in args.frame_range.split(":"))
    n = write_job(args.dir, args.spp, first, stop, args.out)
    print(f"job of {n} frames ({args.dir} to {args.spp} spp, frames {first}..{stop - 1}): {args.out} "
          f"({args.out.stat().st_size / 1e6:.2f} MB)")
    return 0


def _render_extras(args: argparse.Namespace) -> int:
    from diviewer.data.capture import parse_shard
    from diviewer.data.refine_extras import render_extras

    s = render_extras(args.job, args.out, parse_shard(args.shard), args.deadline)
    print(f"done: {s['present']} of {s['frames']} frames of the shard in {args.out} ({s['rendered']} rendered "
          f"in {s['seconds']:.0f} s)")
    return 0


def _area_direct(args: argparse.Namespace) -> int:
    from diviewer.data.area import area_direct

    area_direct(args.dir, args.out, args.samples, partial=args.partial)
    return 0


def _filter_truth(args: argparse.Namespace) -> int:
    from diviewer.data.truth_filter import TruthFilter, filter_dataset

    filter_dataset(args.dir, args.out, TruthFilter(args.levels, args.normal_power, args.plane, args.range_sigma),
                   partial=args.partial)
    return 0


ACTIONS = {"check": _check, "merge": _merge, "refine": _refine, "refine-job": _refine_job,
           "render-extras": _render_extras, "area-direct": _area_direct, "filter-truth": _filter_truth}
"""What each `diviewer data` action runs."""


def run(args: argparse.Namespace) -> int:
    """The action `args.data_command` names."""
    return ACTIONS[args.data_command](args)


def _add_partial_arg(q) -> None:
    q.add_argument("--partial", action="store_true",
                   help="derive the present frames of an incomplete source (each still verified); without it an "
                        "incomplete source is refused")


def add_parser(sub) -> None:
    """`diviewer data ACTION`: one subparser per action of `ACTIONS`."""
    p = sub.add_parser("data", help="inspect datasets")
    data = p.add_subparsers(dest="data_command", required=True, metavar="ACTION")
    p.set_defaults(func=run)
    q = data.add_parser("check", help="verify every frame: present, readable, finite, shapes, checksum")
    q.add_argument("dir", type=Path)
    q.add_argument("--fast", action="store_true", help="skip checksums")
    q = data.add_parser("merge", help="merge shards captured into separate folders")
    q.add_argument("sources", type=Path, nargs="+")
    add_out(q, None)
    q = data.add_parser("refine", help="raise a path-traced dataset's sample count into a new folder (renders only "
                                       "the extra samples; resumable)")
    q.add_argument("dir", type=Path)
    add_number(q, "--spp", required=True, help="the refined dataset's samples per pixel (above the source's)")
    add_out(q, None)
    q.add_argument("--shard", default=None, help="k/n: refine every n-th frame starting at the k-th")
    q.add_argument("--extras", type=Path, default=None, help="a folder of extra samples rendered elsewhere "
                   "(`data refine-job`, then `data render-extras` there): refine only its frames, from them")
    _add_partial_arg(q)
    q = data.add_parser("refine-job", help="write what a refinement's extra samples need, for a range of frames, to "
                                           "render them on another machine (`data render-extras`)")
    q.add_argument("dir", type=Path)
    add_number(q, "--spp", required=True, help="the refined dataset's samples per pixel (above the source's)")
    add_number(q, "--frames", dest="frame_range", type=str, required=True, metavar="A:B",
               help="A:B: the present frames with A <= index < B")
    add_out(q, "the job file (LZMA-compressed JSON)")
    q = data.add_parser("render-extras", help="render a refinement job's extra samples (this shard's frames) into a "
                                              "folder, for `data refine --extras` (resumable)")
    q.add_argument("job", type=Path)
    add_out(q, "the folder of extra samples")
    q.add_argument("--shard", default=None, help="k/n: every n-th frame of the job starting at the k-th")
    add_number(q, "--deadline", type=float, default=None, help="begin no frame after this Unix time")
    q = data.add_parser("area-direct", help="re-render a dataset's GL direct light over each pixel's area into a new "
                                            "folder (supersampled, box-filtered; minutes; resumable)")
    q.add_argument("dir", type=Path)
    add_number(q, "--samples", default=4, help="samples per axis (default 4: 16 per pixel)")
    add_out(q, None)
    _add_partial_arg(q)
    q = data.add_parser("filter-truth", help="filter a path-traced dataset's indirect light over each surface into a new "
                                             "folder (seconds; resumable)")
    q.add_argument("dir", type=Path)
    add_out(q, None)
    add_number(q, "--levels", default=1, help="a-trous levels (default 1: the 5x5 neighbourhood)")
    add_number(q, "--normal-power", type=float, default=32.0, help="exponent of the normals' cosine (default 32)")
    add_number(q, "--plane", type=float, default=0.01,
               help="distance from the tangent plane, over the depth, at which a weight falls to 1/e (default 0.01)")
    add_number(q, "--range-sigma", type=float, default=0.0,
               help="the range term: the relative difference of the light (filtered by one level) at which a "
                    "weight falls to 1/e (default 0: geometry alone)")
    _add_partial_arg(q)
