"""The `diviewer build` command line: a scene and a recipe in, a shipped model out (see docs/build.md)."""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path


def add_build_parser(subparsers) -> argparse.ArgumentParser:
    """The `build` subcommand; it calls `run_build_command`."""
    p = subparsers.add_parser(
        "build", help="one resumable pipeline from a scene to its shipped model: capture, check, evaluation set, "
                      "train and export each K of the ladder, evaluate, pick the smallest sufficient K, ship",
        description="Build a scene's model with a recipe (assets/recipes/*.toml). Every stage resumes: run the same "
                    "command again after an interruption. Uses CUDA (Mitsuba cuda_ad_rgb, torch) where present.")
    p.add_argument("--scene", default=None,
                   help="a shipped scene's name (cornell, sponza, atrium) or a .toml path "
                        "(default: the recipe's scene)")
    p.add_argument("--recipe", default=None, metavar="R",
                   help="a shipped recipe's name (cornell, sponza, paper) or a .toml file (default: the scene's own "
                        "recipe where one is shipped, else cornell's, the best measured)")
    p.add_argument("--work", type=Path, default=None,
                   help="folder of the data, evaluation set, runs, models and the state file (default runs/SCENE)")
    p.add_argument("--ship", type=Path, default=None,
                   help="folder the chosen model goes to as SCENE.onnx with its card (default: assets/models for a "
                        "shipped scene, else the work folder)")
    p.add_argument("--budget", type=float, default=None, metavar="HOURS",
                   help="scale the recipe's frames and steps (never up) so the estimate fits in HOURS on this machine")
    p.add_argument("--evalset", type=Path, default=None, metavar="DIR",
                   help="score on this evaluation set of the scene (e.g. the shipped compact one, "
                        "assets/evalsets/SCENE) instead of rendering the recipe's: the evaluation-set stage then "
                        "only checks it")
    p.add_argument("--ks", type=int, nargs="+", default=None, metavar="K",
                   help="the widths to train instead of the recipe's ladder")
    p.add_argument("--device", default=None, help="training device: auto (default: CUDA where present), cpu, cuda:N")
    p.add_argument("--stop-after", default=None, metavar="STAGE",
                   help="stop once this stage of the plan is done (capture, refine, filter, check, evalset, "
                        "train_k8, ...): render the data here and train later or elsewhere; the same command without it goes on")
    p.add_argument("--dry-run", action="store_true", help="print the plan and its estimated time; do nothing")
    p.set_defaults(func=run_build_command)
    return p


def default_recipe(scene: str) -> str:
    """The scene's own shipped recipe if there is one (cornell, sponza), else the default (cornell's)."""
    from diviewer.train.recipe import DEFAULT_RECIPE, shipped_recipes

    return scene if scene in shipped_recipes() else DEFAULT_RECIPE


def rebuild_command(args: argparse.Namespace) -> str:
    """The command that rebuilds what this one builds (the card records it): the options that change the plan."""
    words = ["diviewer", "build", "--scene", str(args.scene)]  # the scene is named even where the recipe has one
    if args.recipe and args.recipe != default_recipe(str(args.scene)):
        words += ["--recipe", str(args.recipe)]
    if args.budget is not None:
        words += ["--budget", f"{args.budget:g}"]
    if args.ks:
        words += ["--ks", *map(str, args.ks)]
    if args.evalset is not None:
        words += ["--evalset", str(args.evalset)]
    return shlex.join(words)


def run_build_command(args: argparse.Namespace) -> int:
    """`diviewer build`: the plan, printed (--dry-run) or run."""
    from diviewer.build.plan import describe, make_plan
    from diviewer.errors import DiviewerError
    from diviewer.paths import models_dir, scenes_dir
    from diviewer.train.recipe import load_recipe

    if args.scene is None and args.recipe is None:
        raise DiviewerError("give a scene (--scene NAME or a .toml path), or a recipe that names one", field="--scene")
    recipe = load_recipe(args.recipe or default_recipe(str(args.scene)))
    if args.scene is None and recipe.scene is None:
        raise DiviewerError("the recipe names no scene ([recipe] scene); give --scene", path=recipe.path,
                            field="recipe.scene")
    scene = args.scene = str(args.scene or recipe.scene)
    shipped = Path(scene).suffix != ".toml" and (scenes_dir() / f"{scene}.toml").is_file()
    work = args.work or Path("runs") / Path(scene).stem
    ship = args.ship or (models_dir() if shipped else work)
    overrides = {"device": args.device} if args.device else None
    if args.ks and any(k < 1 for k in args.ks):
        raise DiviewerError(f"widths must be positive, got {args.ks}", field="--ks")
    plan = make_plan(scene, recipe, work, ship=ship, budget_hours=args.budget,
                     ks=tuple(sorted(set(args.ks))) if args.ks else None, train_overrides=overrides,
                     evalset_dir=args.evalset)
    names = [s.name for s in plan.stages]
    if args.stop_after is not None and args.stop_after not in names:
        raise DiviewerError(f"'{args.stop_after}' is not a stage of this build's plan ({', '.join(names)})",
                            field="--stop-after")
    if args.dry_run:
        from diviewer.build.pace import measured_pace
        from diviewer.build.pipeline import finished_stages

        paces = measured_pace(plan)
        try:
            done, refusal = finished_stages(plan) | {p.stage for p in paces if p.done}, None
        except DiviewerError as exc:  # the work folder holds another plan's build: the run would stop there
            done, refusal = set(), exc
        for line in [*describe(plan, done, {p.stage: p.left for p in paces if p.left is not None}),
                     *(p.line for p in paces)]:
            print(line)
        if args.stop_after is not None:
            after = names[names.index(args.stop_after) + 1:]
            print(f"--stop-after {args.stop_after}: a run stops there" + (f"; not run: {', '.join(after)}" if after else ""))
        if refusal is not None:
            print("dry run: nothing was done; a run of this command would refuse the work folder (below)")
            raise refusal
        print(f"dry run: nothing was done; run it without --dry-run ({rebuild_command(args)})")
        return 0
    from diviewer.build.pipeline import BuildInterrupted, run_build

    try:
        run_build(plan, rebuild_command(args), stop_after=args.stop_after)
    except BuildInterrupted as exc:
        print(f"diviewer build: stopped ({exc}); run the same command again to resume")
        return 130
    return 0
