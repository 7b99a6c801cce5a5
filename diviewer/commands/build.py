"""The `diviewer build` command line: a scene and a recipe in, a shipped model out (see docs/build.md)."""

from __future__ import annotations

import argparse
import contextlib
import shlex
from pathlib import Path

from diviewer.commands.common import add_number, add_scene


def add_parser(subparsers) -> argparse.ArgumentParser:
    """The `build` subcommand; it calls `run`."""
    p = subparsers.add_parser(
        "build", help="one resumable pipeline from a scene to its shipped model: capture, check, evaluation set, "
                      "train and export each K of the ladder, evaluate, pick the smallest sufficient K, ship",
        description="Build a scene's model with a recipe (assets/recipes/*.toml). Every stage resumes: run the same "
                    "command again after an interruption. Uses CUDA (Mitsuba cuda_ad_rgb, torch) where present.")
    add_scene(p, default=None, help="a shipped scene's name (cornell, sponza, atrium) or a .toml path "
                                    "(default: the recipe's scene)")
    p.add_argument("--recipe", default=None, metavar="R",
                   help="a shipped recipe's name (cornell, sponza, paper) or a .toml file (default: the scene's own "
                        "recipe where one is shipped, else cornell's, the best measured)")
    p.add_argument("--work", type=Path, default=None,
                   help="folder of the data, evaluation set, runs, models and the state file (default runs/SCENE)")
    p.add_argument("--ship", type=Path, default=None, metavar="DIR",
                   help="folder the chosen model goes to as SCENE.onnx with its card (default: the work folder, for "
                        "every scene). A model file there is replaced only with --ship, after both models are scored "
                        "on the same evaluation set: one that scores better is kept (and the build refused) unless "
                        "--replace-worse; the replaced files are kept in WORK/replaced. To rebuild a shipped model "
                        "in place: --ship assets/models")
    p.add_argument("--replace-worse", action="store_true",
                   help="with --ship: replace the model there even where it scores better than the new one")
    add_number(p, "--budget", type=float, default=None, metavar="HOURS",
               help="scale the recipe's frames and steps (never up) so the estimate fits in HOURS on this machine")
    p.add_argument("--evalset", type=Path, default=None, metavar="DIR",
                   help="score on this evaluation set of the scene (e.g. the shipped compact one, "
                        "assets/evalsets/SCENE) instead of rendering the recipe's: the evaluation-set stage then "
                        "only checks it")
    add_number(p, "--ks", nargs="+", default=None, metavar="K",
               help="the widths to train instead of the recipe's ladder (each 1 to 256)")
    p.add_argument("--device", default=None, help="training device: auto (default: CUDA where present), cpu, cuda:N")
    p.add_argument("--stop-after", default=None, metavar="STAGE",
                   help="stop once this stage of the plan is done (capture, refine, filter, check, evalset, "
                        "train_k8, ...): render the data here and train later or elsewhere; the same command without it goes on")
    p.add_argument("--dry-run", action="store_true", help="print the plan and its estimated time; do nothing")
    p.set_defaults(func=run)
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


def run(args: argparse.Namespace) -> int:
    """`diviewer build`: the plan, printed (--dry-run) or run."""
    from diviewer.builder.checks import check_device, check_folders, check_ks, check_replacement, check_splits
    from diviewer.builder.plan import describe, make_plan
    from diviewer.errors import DiviewerError
    from diviewer.paths import default_work_dir
    from diviewer.train.recipe import load_recipe

    if args.scene is None and args.recipe is None:
        raise DiviewerError("give a scene (--scene NAME or a .toml path), or a recipe that names one", field="--scene")
    recipe = load_recipe(args.recipe or default_recipe(str(args.scene)))
    if args.scene is None and recipe.scene is None:
        raise DiviewerError("the recipe names no scene ([recipe] scene); give --scene", path=recipe.path,
                            field="recipe.scene")
    scene = args.scene = str(args.scene or recipe.scene)
    work = args.work or default_work_dir(scene)
    ship = args.ship or work  # a model elsewhere is replaced only where --ship names its folder
    if args.replace_worse and args.ship is None:
        raise DiviewerError("--replace-worse applies to a model replaced in the folder --ship names; give --ship DIR",
                            field="--replace-worse")
    overrides = {"device": args.device} if args.device else None
    if args.ks:
        check_ks(args.ks)
    check_folders(work, ship)
    device = args.device or recipe.train.get("device")
    check_device(device, "--device" if args.device else "train.device", None if args.device else recipe.path)
    from diviewer.builder.calibrate import keep_calibration, plan_basis  # noqa: F401 (keep_calibration: dry run)

    make_plan(scene, recipe, work, ship=ship, ks=tuple(sorted(set(args.ks))) if args.ks else None,
              train_overrides=overrides, evalset_dir=args.evalset)  # every input checked before the scene is timed
    # the timing is kept once the command is accepted: a refused one leaves nothing behind
    cost_basis, timing = plan_basis(scene, recipe, work, keep=False)
    plan = make_plan(scene, recipe, work, ship=ship, budget_hours=args.budget,
                     ks=tuple(sorted(set(args.ks))) if args.ks else None, train_overrides=overrides,
                     evalset_dir=args.evalset, basis=cost_basis)
    check_splits(plan.capture, recipe.path)
    replacing = check_replacement(plan, args.ship is not None, args.replace_worse)
    names = [s.name for s in plan.stages]
    if args.stop_after is not None and args.stop_after not in names:
        raise DiviewerError(f"'{args.stop_after}' is not a stage of this build's plan ({', '.join(names)})",
                            field="--stop-after")
    if args.dry_run:
        from diviewer.builder.pace import measured_pace
        from diviewer.builder.pipeline import finished_stages

        paces = measured_pace(plan)
        try:
            done, refusal = finished_stages(plan) | {p.stage for p in paces if p.done}, None
        except DiviewerError as exc:  # the work folder holds another plan's build: the run would stop there
            done, refusal = set(), exc
        for line in [*describe(plan, done, {p.stage: p.left for p in paces if p.left is not None}),
                     *(p.line for p in paces), *([replacing] if replacing else [])]:
            print(line)
        if args.stop_after is not None:
            after = names[names.index(args.stop_after) + 1:]
            print(f"--stop-after {args.stop_after}: a run stops there" + (f"; not run: {', '.join(after)}" if after else ""))
        from diviewer.locks import holder

        if (running := holder(work)) is not None:
            print(f"a run of this command would refuse the work folder now: another run is writing there: {running}")
        if refusal is not None:
            print("dry run: nothing was done; a run of this command would refuse the work folder (below)")
            raise refusal
        if work.is_dir() and running is None:  # a dry run makes no folder, nor writes beside a run
            keep_calibration(work, timing)
        print(f"dry run: nothing was done but timing the scene; run it without --dry-run ({resume_command(args)})")
        return 0
    from diviewer.builder.pipeline import BuildInterrupted, run_build

    if replacing:
        print(replacing)
    try:
        with interrupts_raise():
            run_build(plan, rebuild_command(args), stop_after=args.stop_after, replace_worse=args.replace_worse,
                      timing=timing)
    except BuildInterrupted as exc:
        where = f" in stage {exc.stage}" if exc.stage else ""
        print(f"diviewer build: stopped{where} ({exc}); resume with: {resume_command(args)}")
        return 130
    return 0


def resume_command(args: argparse.Namespace) -> str:
    """The command line that resumes this build: the rebuild command with the folders and the run's options."""
    words = shlex.split(rebuild_command(args))
    for option, value in (("--work", args.work), ("--ship", args.ship), ("--device", args.device)):
        if value is not None:
            words += [option, str(value)]
    if args.replace_worse:
        words.append("--replace-worse")
    return shlex.join(words)


@contextlib.contextmanager
def interrupts_raise():
    """SIGTERM raises `BuildInterrupted` within the block, as Ctrl-C raises KeyboardInterrupt, so that a build ended
    politely says where it stopped and how to resume (a training stage saves its last.ckpt first, by its own
    handler); the former handler comes back after. A process forked meanwhile (the scoring's workers) dies of it as
    before."""
    import os
    import signal
    import threading

    from diviewer.builder.pipeline import STOP_SIGNALS, BuildInterrupted

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pid, before = os.getpid(), signal.getsignal(signal.SIGTERM)

    def stop(signum, _frame):
        if os.getpid() != pid:
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
            return
        STOP_SIGNALS.append(signal.Signals(signum).name)
        raise BuildInterrupted(signal.Signals(signum).name)

    STOP_SIGNALS.clear()
    signal.signal(signal.SIGTERM, stop)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, before)
