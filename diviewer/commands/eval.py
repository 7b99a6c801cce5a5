"""`diviewer eval`: models against an evaluation set or a dataset split, beside direct light alone."""

from __future__ import annotations

import argparse
from pathlib import Path

from diviewer.commands.common import add_model, add_number, add_out, add_provider, add_split
from diviewer.errors import DiviewerError


def run(args: argparse.Namespace) -> int:
    """Score the models on an evaluation set (default the shipped compact one) or on a dataset's split."""
    from diviewer.evaluation.evaluate import evaluate, evaluate_evalset

    if args.evalset is not None and args.data is not None:
        raise DiviewerError("give an evaluation set (--evalset DIR) or a dataset split (--data DIR), not both",
                            field="--evalset")
    if args.data is None:  # no --evalset: the scene's compact set shipped in assets/evalsets/
        evaluate_evalset(args.model, args.evalset, provider=args.provider, out=args.out, partial=args.partial,
                         jobs=jobs(args), exposure=args.exposure)
        return 0
    if args.partial:
        raise DiviewerError("--partial applies to evaluation sets, not to --data", field="--partial")
    if len(args.model) == 1:
        evaluate(args.model[0], args.data, split=args.split, provider=args.provider, out=args.out,
                 exposure=args.exposure)
        return 0
    results = [evaluate(m, args.data, split=args.split, provider=args.provider, exposure=args.exposure)
               for m in args.model]
    if args.out is not None:
        from diviewer.outputs import write_json

        write_json(args.out, {"results": results})
    return 0


def jobs(args: argparse.Namespace) -> int:
    """``--jobs``, or this machine's cores where it is not given."""
    from diviewer.evaluation.scoring import default_jobs

    if args.jobs is None:
        return default_jobs()
    if args.jobs < 1:
        raise DiviewerError(f"must be at least 1, got {args.jobs}", field="--jobs")
    return args.jobs


def add_jobs(p) -> None:
    """``--jobs``: the processes scoring runs in."""
    add_number(p, "--jobs", default=None,
               help="processes the images are scored in (default: this machine's cores); scoring, HDR-FLIP "
                    "above all, is most of an evaluation's time")


def add_parser(sub) -> None:
    """`diviewer eval`."""
    p = sub.add_parser("eval", help="models against an evaluation set (PSNR, SSIM, FLIP, equivalent spp) or a "
                                    "dataset split, beside direct light alone")
    add_model(p, "an ONNX model (diviewer export, or diviewer baseline); repeat for several", action="append",
              required=True)
    p.add_argument("--evalset", type=Path, default=None,
                   help="an evaluation set (diviewer evalset): every split; default the scene's compact set "
                        "(assets/evalsets/<scene>)")
    p.add_argument("--partial", action="store_true",
                   help="score an incomplete evaluation set's present frames (and list them); refused without it")
    p.add_argument("--data", type=Path, default=None, help="or a dataset of the model's scene (diviewer capture)")
    add_split(p, "test", "with --data")
    add_provider(p)
    add_out(p, "write the results as JSON (strict: no NaN/Infinity)", required=False)
    add_jobs(p)
    add_number(p, "--exposure", type=str, default="scene",
               help="the tone map's exposure for the tm metrics: scene (default: the evaluation set's one exposure), "
                    "metered (each frame at the exposure the viewer's meter gives its path-traced truth, as a scene "
                    "with auto_exposure is shown; an unlit frame keeps the scene's) or a number of stops for every "
                    "frame")
    p.set_defaults(func=run)
