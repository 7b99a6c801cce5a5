"""The `diviewer ship` command line: `model`, `eval` and `ladder` (docs/build.md, "A model trained by hand")."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from diviewer.commands.common import add_model, add_number


def add_parser(subparsers) -> argparse.ArgumentParser:
    """The `ship` subcommand and its three actions (`ACTIONS`)."""
    p = subparsers.add_parser(
        "ship", help="ship a model trained by hand with its card, record a later evaluation or a K ladder in it",
        description="Ship a model trained by hand (what `diviewer build` does at its end), record a later "
                    "evaluation of the shipped weights in its card, or record a K ladder measured by hand. The card "
                    "(SCENE.json) and the model's ONNX metadata are written together.")
    sub = p.add_subparsers(dest="ship_command", required=True, metavar="ACTION")
    p.set_defaults(func=run)
    m = sub.add_parser("model", help="an exported model becomes its scene's shipped model (SCENE.onnx), with its card")
    add_model(m, "an exported model (its card beside it)", required=True)
    m.add_argument("--run", type=Path, required=True, help="its training run (curves.png, metrics.csv)")
    m.add_argument("--eval", type=Path, required=True, help="diviewer eval JSON of it and the shipped model")
    m.add_argument("--previous-eval", type=Path, default=None,
                   help="the shipped model's eval JSON on the same frames, where the scene file changes with this "
                        "model (default: --eval holds both)")
    m.add_argument("--command", action="append", required=True, dest="commands",
                   help="how it was made, one command each")
    m.add_argument("--note", required=True, help="what it is, in a sentence or two")
    m.add_argument("--ladder-why", required=True, help="why this K (the ladder's verdict)")
    m.add_argument("--ladder-file", default=None, help="the ladder record beside it (default SCENE_ladder.json)")
    m.add_argument("--ladder-run", nargs=2, action="append", default=[], metavar=("K", "RUN"),
                   help="a K of the ladder and its training run (or the run's metrics.csv), once per K: their "
                        "curves on one figure, SCENE_ladder_curves.png (the card's ladder.curves)")
    m.add_argument("--ship", type=Path, default=None, metavar="DIR", help="where it goes (default assets/models)")
    m.add_argument("--replace-worse", action="store_true",
                   help="replace the model there even where it scores better on the same frames than this one")
    e = sub.add_parser("eval", help="record a `diviewer eval` of the shipped weights in the model's card")
    e.add_argument("--eval", type=Path, required=True, help="diviewer eval JSON that scored the model")
    add_model(e, "the shipped model (its card beside it)", required=True)
    e.add_argument("--method", default=None, help="the model's name in the JSON (default: the file's stem)")
    e.add_argument("--key", default="evalset_full", help="the card's field for the record (default evalset_full)")
    ld = sub.add_parser("ladder", help="a K ladder's record from eval JSONs; with --ship, its verdict on the card")
    ld.add_argument("--scene", required=True, help="the scene's name (the shipped SCENE.onnx)")
    ld.add_argument("--test-split", type=Path, required=True,
                    help="`diviewer eval --data CAPTURE --split test` JSON of the models")
    ld.add_argument("--evalset", type=Path, required=True, help="`diviewer eval` JSON of the models on the "
                    "evaluation set (the rule's figure)")
    ld.add_argument("--model", action="append", required=True, metavar="KN=PATH", help="a K and its model, once "
                    "per K (K8=assets/models/cornell.onnx)")
    add_number(ld, "--tolerance", type=float, default=0.5, help="dB below the best K that still suffices")
    ld.add_argument("--ship", type=Path, default=None, metavar="DIR",
                    help="write SCENE_ladder.json there and the verdict on its SCENE.onnx's card")
    ld.add_argument("--note", default="", help="added to the verdict")
    return p


def _model(args) -> int:
    from diviewer.paths import models_dir
    from diviewer.ship.model import mean_psnr, ship

    dest = args.ship or models_dir()
    runs = {int(k): Path(run) for k, run in args.ladder_run}
    card = ship(args.model, args.run, args.eval, args.commands, args.note, args.ladder_why, args.ladder_file, dest,
                args.previous_eval, runs, replace_worse=args.replace_worse)
    compact = card["evalset_compact"]
    print(f"shipped {args.model} as {dest / (card['scene'] + '.onnx')} (K={card['K']}), replacing the model there: "
          f"{mean_psnr(compact['this_model']):.2f} dB against its {mean_psnr(compact['previous_shipped']):.2f} "
          f"(tone-mapped PSNR, the mean of the splits)")
    return 0


def _eval(args) -> int:
    from diviewer.ship.card import record_eval

    card = record_eval(args.model, args.eval, args.key, args.method)
    print(f"{args.model}: {args.key} recorded from {args.eval} ({', '.join(card[args.key]['this_model'])})")
    return 0


def _ladder(args) -> int:
    from diviewer.errors import DiviewerError
    from diviewer.ship.ladder import record_ladder

    models = {}
    for m in args.model:
        k, sep, path = m.partition("=")
        if not sep or not k.lstrip("Kk").isdigit():
            raise DiviewerError(f"--model {m}: give KN=PATH (K8=assets/models/cornell.onnx)", field="--model")
        models[int(k.lstrip("Kk"))] = Path(path)
    record = record_ladder(args.scene, args.test_split, args.evalset, models, args.tolerance, args.ship, args.note)
    print(json.dumps(record, indent=1))
    return 0


ACTIONS = {"model": _model, "eval": _eval, "ladder": _ladder}
"""What each `diviewer ship` action runs."""


def run(args: argparse.Namespace) -> int:
    """The action `args.ship_command` names."""
    return ACTIONS[args.ship_command](args)
