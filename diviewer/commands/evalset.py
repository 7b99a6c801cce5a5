"""`diviewer evalset`: a scene's fixed evaluation set (truth, its noise floor, a ladder of lower sample counts), or
the compact set of one."""

from __future__ import annotations

import argparse
from pathlib import Path

from diviewer.commands.common import add_number, add_out, add_scene, add_variant
from diviewer.commands.eval import add_jobs, jobs
from diviewer.errors import DiviewerError


def add_parser(sub) -> None:
    """`diviewer evalset`."""
    p = sub.add_parser("evalset", help="render a scene's fixed evaluation set: >= 1024-spp truth, its noise floor "
                                       "and a ladder of lower sample counts (resumable)")
    add_scene(p)
    add_out(p, "evaluation set folder (created, or resumed)")
    add_number(p, "--frames-per-split", default=None,
               help="frames in each split (default 24; with --compact 6 of each split, spread over its meshes, "
                    "or the fewest a split has; more than a split has is refused)")
    p.add_argument("--res", default="128", help="the model's frame, N or WxH (square splits); default 128")
    p.add_argument("--window-widths", default=None,
                   help="widths of the window_shapes split at the same rows (default 4:3 and 16:9: 170,228 at 128)")
    p.add_argument("--compact", type=Path, default=None, metavar="FULL_DIR",
                   help="write the compact set of the full evaluation set FULL_DIR into --out, a new folder (what "
                        "assets/evalsets ships) instead of rendering; a set already there is never overwritten")
    add_number(p, "--spp", default=1024, help="samples per pixel of the ground truth (default 1024)")
    p.add_argument("--ladder", default=",".join(map(str, (1, 4, 16, 64, 256))),
                   help="lower sample counts for the equivalent spp (default 1,4,16,64,256)")
    add_number(p, "--max-depth", default=16, help="path length limit of the full renders")
    add_number(p, "--seed", default=0, help="which evaluation set of its own seed stream (default 0)")
    p.add_argument("--shard", default=None,
                   help="k/n: render every n-th frame starting at the k-th, beside the other shards in one folder")
    add_jobs(p)
    add_variant(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Render the evaluation set the options describe (resumable), or write the compact set of one (--compact)."""
    from diviewer.data.capture import parse_shard
    from diviewer.evaluation.evalset import EvalSetSettings, build_evalset
    from diviewer.frames import parse_resolution
    from diviewer.locks import run_lock, shard_part

    if args.compact is not None:
        from diviewer.evaluation.frames import write_compact

        write_compact(args.compact, args.out, frames_per_split=args.frames_per_split, jobs=jobs(args))
        return 0
    width, height = parse_resolution(args.res)
    try:
        ladder = tuple(int(x) for x in args.ladder.split(","))
    except ValueError:
        raise DiviewerError(f"--ladder takes sample counts like 1,4,16, got '{args.ladder}'",
                            field="--ladder") from None
    windows = None
    if args.window_widths is not None:
        try:
            windows = tuple(int(x) for x in args.window_widths.split(","))
        except ValueError:
            raise DiviewerError(f"--window-widths takes widths like 170,228, got '{args.window_widths}'",
                                field="--window-widths") from None
    n = 24 if args.frames_per_split is None else args.frames_per_split
    settings = EvalSetSettings(frames_per_split=n, width=width, height=height,
                               window_widths=windows, spp=args.spp, ladder=ladder, max_depth=args.max_depth,
                               seed=args.seed)
    k, n = parse_shard(args.shard)
    with run_lock(args.out, "evalset", shard_part(k, n)):  # a second run of the same frames refuses at once
        build_evalset(args.scene, args.out, settings, shard=(k, n), jobs=jobs(args))
    return 0
