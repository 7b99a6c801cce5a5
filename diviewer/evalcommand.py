"""The `diviewer eval` and `diviewer evalset` subcommands: their options and what they run."""

from __future__ import annotations

import argparse
from pathlib import Path

from diviewer.errors import DiviewerError
from diviewer.paths import scene_help


def _cmd_eval(args: argparse.Namespace) -> int:
    from diviewer.evaluation.evaluate import evaluate, evaluate_evalset, strict_json

    if args.evalset is not None and args.data is not None:
        raise DiviewerError("give an evaluation set (--evalset DIR) or a dataset split (--data DIR), not both",
                            field="--evalset")
    if args.data is None:  # no --evalset: the scene's compact set shipped in assets/evalsets/
        evaluate_evalset(args.model, args.evalset, provider=args.provider, out=args.out, partial=args.partial,
                         jobs=_jobs(args))
        return 0
    if args.partial:
        raise DiviewerError("--partial applies to evaluation sets, not to --data", field="--partial")
    if len(args.model) == 1:
        evaluate(args.model[0], args.data, split=args.split, provider=args.provider, out=args.out)
        return 0
    results = [evaluate(m, args.data, split=args.split, provider=args.provider) for m in args.model]
    if args.out is not None:
        from diviewer import imageio

        imageio.write_text(args.out, strict_json({"results": results}))
    return 0


def _jobs(args: argparse.Namespace) -> int:
    from diviewer.evaluation.scoring import default_jobs

    if args.jobs is None:
        return default_jobs()
    if args.jobs < 1:
        raise DiviewerError(f"must be at least 1, got {args.jobs}", field="--jobs")
    return args.jobs


def _add_jobs_arg(p) -> None:
    p.add_argument("--jobs", type=int, default=None,
                   help="processes the images are scored in (default: this machine's cores); scoring, HDR-FLIP "
                        "above all, is most of an evaluation's time")


def _cmd_evalset(args: argparse.Namespace) -> int:
    from diviewer.data.capture import parse_shard
    from diviewer.evaluation.evalset import EvalSetSettings, build_evalset
    from diviewer.frames import parse_resolution
    from diviewer.locks import run_lock, shard_part

    if args.compact is not None:
        from diviewer.evaluation.frames import write_compact

        write_compact(args.compact, args.out, frames_per_split=args.frames_per_split, jobs=_jobs(args))
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
        build_evalset(args.scene, args.out, settings, shard=(k, n), jobs=_jobs(args))
    return 0


def add_eval_parsers(sub, add_variant_arg) -> None:
    """Add ``eval`` and ``evalset`` to the subcommands (``add_variant_arg``: the Mitsuba variant option)."""
    p = sub.add_parser("eval", help="models against an evaluation set (PSNR, SSIM, FLIP, equivalent spp) or a "
                                    "dataset split, beside direct light alone")
    p.add_argument("--model", type=Path, action="append", required=True,
                   help="an ONNX model (diviewer export, or diviewer baseline); repeat for several")
    p.add_argument("--evalset", type=Path, default=None,
                   help="an evaluation set (diviewer evalset): every split; default the scene's compact set "
                        "(assets/evalsets/<scene>)")
    p.add_argument("--partial", action="store_true",
                   help="score an incomplete evaluation set's present frames (and list them); refused without it")
    p.add_argument("--data", type=Path, default=None, help="or a dataset of the model's scene (diviewer capture)")
    p.add_argument("--split", default="test", choices=("train", "val", "test"), help="with --data")
    p.add_argument("--provider", default=None, choices=("cpu", "cuda", "tensorrt"))
    p.add_argument("--out", type=Path, default=None, help="write the results as JSON (strict: no NaN/Infinity)")
    _add_jobs_arg(p)
    p.set_defaults(func=_cmd_eval)


    p = sub.add_parser("evalset", help="render a scene's fixed evaluation set: >= 1024-spp truth, its noise floor "
                                       "and a ladder of lower sample counts (resumable)")
    p.add_argument("--scene", default="cornell", help=scene_help())
    p.add_argument("--out", type=Path, required=True, help="evaluation set folder (created, or resumed)")
    p.add_argument("--frames-per-split", type=int, default=None,
                   help="frames in each split (default 24; with --compact 6 of each split, spread over its meshes, "
                        "or the fewest a split has; more than a split has is refused)")
    p.add_argument("--res", default="128", help="the model's frame, N or WxH (square splits); default 128")
    p.add_argument("--window-widths", default=None,
                   help="widths of the window_shapes split at the same rows (default 4:3 and 16:9: 170,228 at 128)")
    p.add_argument("--compact", type=Path, default=None, metavar="FULL_DIR",
                   help="write the compact set of the full evaluation set FULL_DIR into --out, a new folder (what "
                        "assets/evalsets ships) instead of rendering; a set already there is never overwritten")
    p.add_argument("--spp", type=int, default=1024, help="samples per pixel of the ground truth (default 1024)")
    p.add_argument("--ladder", default=",".join(map(str, (1, 4, 16, 64, 256))),
                   help="lower sample counts for the equivalent spp (default 1,4,16,64,256)")
    p.add_argument("--max-depth", type=int, default=16, help="path length limit of the full renders")
    p.add_argument("--seed", type=int, default=0, help="which evaluation set of its own seed stream (default 0)")
    p.add_argument("--shard", default=None,
                   help="k/n: render every n-th frame starting at the k-th, beside the other shards in one folder")
    _add_jobs_arg(p)
    add_variant_arg(p)
    p.set_defaults(func=_cmd_evalset)
