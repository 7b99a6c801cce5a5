"""`diviewer build`'s stages, run in order, each skipped when the state file says it finished and its outputs
are unchanged: capture, check, evaluation set, train and export each K, score them, pick the smallest sufficient
K, ship it with its card."""

from __future__ import annotations

import json
import math
import os
import shutil
import sys
import time
from pathlib import Path
from typing import Any, Callable

from diviewer import imageio
from diviewer.builder.actuals import keep_actuals
from diviewer.builder.pace import measured_pace, missing_link
from diviewer.builder.plan import RUN_ONLY, Plan, describe
from diviewer.builder.scores import PICK_MEASURE, evalset_psnr_tm, evalset_scores, means_on_test_split
from diviewer.builder.shipfiles import write_ladder_curves, write_model_card
from diviewer.builder.state import BuildState
from diviewer.data.dataset import sha256_file
from diviewer.console import overall, progress_bar
from diviewer.errors import DiviewerError

STATE_FILE = "build.json"


STOP_SIGNALS: list[str] = []
"""The stop signals a running build received (its SIGTERM handler appends them): an error that a library raises after
one (Mitsuba wraps an exception raised inside its render in its own) is that stop, not a failure."""


class BuildInterrupted(Exception):
    """A stage stopped before its end (Ctrl-C, SIGTERM): the build stops, and resumes when run again."""

    def __init__(self, why: str, stage: str | None = None):
        super().__init__(why)
        self.stage = stage
        """The stage it stopped in (None: before the first)."""


def plan_key(plan: Plan) -> dict[str, Any]:
    """What a work folder's build is: a different key is another build, refused in the same folder."""
    import dataclasses

    from diviewer.scene.loader import resolve_scene_path
    from diviewer.train.recipe import export_settings

    return json.loads(json.dumps({
        "scene": scene_key(resolve_scene_path(plan.scene), plan.work),
        "recipe": {"name": plan.recipe.name, "sha256": plan.recipe.sha256,
                   "content_sha256": plan.recipe.content_sha256(), "model_sha256": plan.recipe.model_sha256()},
        "export": dataclasses.asdict(export_settings(plan.recipe)),
        "capture": dataclasses.asdict(plan.capture), "evalset": dataclasses.asdict(plan.evalset),
        **({"refine_spp": plan.refine_spp} if plan.refine_spp is not None else {}),  # absent: every build before it
        **({"truth_filter": plan.truth_filter.record()} if plan.truth_filter is not None else {}),  # absent: as before
        **({"given_evalset": evalset_key(plan.given_evalset, plan.work)} if plan.given_evalset is not None else {}),
        "train": {k: v for k, v in plan.train.items() if k not in RUN_ONLY}, "ks": list(plan.ks)}, default=str))


def scene_key(path: Path, work: Path) -> dict[str, str]:
    """A build's scene by identity (`diviewer.scene.identity`: its file and every file it loads) and by its path
    from the work folder, so that a project moved with its scene is the same build (`BuildState`)."""
    from diviewer.scene.loader import load_scene

    return {"hash": load_scene(path).file_hash, "path": os.path.relpath(path.resolve(), Path(work).resolve())}


def evalset_key(path: Path, work: Path) -> dict[str, str]:
    """An evaluation set made before (``--evalset``) by identity (its manifest's sha256) and by its path from the
    work folder, as `scene_key` names the scene."""
    return {"manifest_sha256": sha256_file(path / "manifest.json"),
            "path": os.path.relpath(path.resolve(), Path(work).resolve())}


def finished_stages(plan: Plan) -> set[str]:
    """Stages a build of this plan in its work folder has finished, with outputs unchanged (none where there is no
    build). Raises the run's own DiviewerError where the folder holds a build of another plan, which a run would
    refuse to touch."""
    if not (plan.work / STATE_FILE).is_file():
        return set()
    state = BuildState(plan.work / STATE_FILE, plan_key(plan))
    return {s.name for s in plan.stages
            if (rec := state.done(s.name, plan.work)) is not None and not _stale(s.name, rec, plan)}


def run_build(plan: Plan, command: str, log: Callable[[str], None] = print,
              stop_after: str | None = None, replace_worse: bool = False, timing: dict | None = None
              ) -> dict[str, Any] | None:
    """Run (or resume) every stage of ``plan``, or those up to the stage named ``stop_after``, holding the work
    folder's lock (a second build there is refused at once); returns the ladder record with the chosen K, or None
    when it stopped before the pick. ``replace_worse``: the ship replaces a model that scores better."""
    from diviewer.locks import run_lock
    from diviewer.outputs import building

    from diviewer.builder.calibrate import keep_calibration

    with run_lock(plan.work, "build", option="--work"), building(plan.work):
        keep_calibration(plan.work, timing)  # the scene's timing (`plan_basis`), kept for the next plan
        return _run(plan, command, log, stop_after, replace_worse)


def _run(plan: Plan, command: str, log, stop_after: str | None, replace_worse: bool) -> dict[str, Any] | None:
    for line in [*describe(plan), *(p.line for p in measured_pace(plan))]:
        log(line)
    if stop_after is not None:
        log(f"stops after {stop_after} (--stop-after)")
    state = BuildState(plan.work / STATE_FILE, plan_key(plan), save_upgrade=True)
    if state.ladder_change is not None:
        was, now = state.ladder_change
        log(f"the K ladder changed from {', '.join(map(str, was))} to {', '.join(map(str, now))}: every K trained "
            f"before keeps its run; the evaluation, the pick and the ship run again over the new ladder")
    if state.train_change is not None:
        was, now = state.train_change
        edits = ", ".join(f"{k} {was.get(k)} -> {now.get(k)}" for k in sorted({*was, *now}) if was.get(k) != now.get(k))
        log(f"the recipe changed before any K was trained ({edits or 'outside [train]'}): every stage done before "
            f"keeps; the training runs with the new settings")
    if state.export_change is not None:
        was, now = state.export_change
        edits = ", ".join(f"{k} {was.get(k)} -> {now.get(k)}" for k in sorted(now) if was.get(k) != now.get(k))
        log(f"the recipe's [export] changed ({edits}): every K trained keeps its run; the export, the evaluation, "
            f"the pick and the ship run again")
    finished = {s.name for s in plan.stages if (rec := state.done(s.name, plan.work)) and not _stale(s.name, rec, plan)}
    tty = sys.stderr.isatty()  # in a log, each stage's own lines carry the build's overall percentage (`overall`)
    bar = progress_bar(max(1, round(plan.seconds)), "build (estimated seconds of work)", "s",
                       initial=round(sum(s.seconds for s in plan.stages if s.name in finished))) if tty else None
    stage, done_s = None, 0.0
    try:
        for i, stage in enumerate(plan.stages, 1):
            if stage.name in finished:
                log(f"[{i}/{len(plan.stages)}] {stage.name}: done before, outputs checked; skipped")
            else:
                log(f"[{i}/{len(plan.stages)}] {stage.name}: {stage.title} (build {done_s / max(plan.seconds, 1):.0%} "
                    f"done)")
                t0 = time.perf_counter()
                kind, _, k = stage.name.partition("_k")
                with overall(plan.seconds, done_s, stage.seconds):
                    outputs, result = STAGES[kind](plan, state, log, k=int(k) if k else None, command=command,
                                                   replace_worse=replace_worse)
                state.finish(stage.name, plan.work, outputs, result, time.perf_counter() - t0)
                if bar is not None:
                    bar.update(round(stage.seconds))
            done_s += stage.seconds
            if stage.name == stop_after and i < len(plan.stages):
                log(f"stopped after {stage.name} as asked (--stop-after); the same command without it goes on "
                    f"from {plan.stages[i].name}")
                keep_actuals(plan, state, log)
                return None
    except KeyboardInterrupt:
        raise BuildInterrupted("interrupted", stage and stage.name) from None
    except BuildInterrupted as exc:
        raise BuildInterrupted(str(exc), exc.stage or (stage and stage.name)) from None
    except Exception:
        if STOP_SIGNALS:
            raise BuildInterrupted(STOP_SIGNALS[-1], stage and stage.name) from None
        raise
    finally:
        if bar is not None:
            bar.close()
    keep_actuals(plan, state, log)
    ladder = state.data["stages"]["pick"]["result"]
    where = state.data["stages"]["ship"]["result"].get("model")
    log(f"built {plan.scene_name}: K={ladder['chosen_K']} ({ladder['rule']})" + (f"; shipped {where}" if where else ""))
    try:
        from diviewer.builder.summary import summary_lines
        from diviewer.train.report import read_metrics

        k = ladder["chosen_K"]
        for line in summary_lines(json.loads((plan.work / "evalset_eval.json").read_text()), plan.model(k).stem,
                                  ladder["rows"], plan.recipe.tolerance_db, read_metrics(plan.run_dir(k) / "metrics.csv")):
            log(line)
    except (OSError, ValueError, KeyError) as exc:  # the model is built; only its summary could not be read
        log(f"(no summary: {type(exc).__name__}: {exc})")
    return ladder


def _stale(stage: str, rec: dict[str, Any], plan: Plan) -> bool:
    """Whether a finished stage must run again although its outputs are intact: a pick made by another rule
    (`PICK_MEASURE`) or under another size cap (the recipe's ``max_mb``), a ship to another folder or of another
    ladder record than the pick's."""
    if stage == "pick":
        return (rec["result"].get("measure") != PICK_MEASURE
                or rec["result"].get("max_mb") != plan.recipe.max_mb)
    if stage == "ship":
        ladder = plan.work / "ladder.json"
        return rec["result"].get("to") != (None if plan.ship is None else str(plan.ship)) or (
            plan.ship is not None and (not ladder.is_file()
                                       or rec["result"].get("ladder_sha256") != sha256_file(ladder)))
    return False


def _capture(plan: Plan, state: BuildState, log, **_) -> tuple[list[Path], dict]:
    from diviewer.data.capture import capture, refined_stand_in

    if (why := missing_link(plan)) is not None:
        raise DiviewerError(why, path=plan.capture_dir)
    summary = (refined_stand_in(plan.scene, plan.capture_dir, plan.capture, log=log)
               or capture(plan.scene, plan.capture_dir, plan.capture, log=log))
    return [plan.capture_dir / "manifest.json"], {k: summary.get(k) for k in ("present", "planned", "per_split",
                                                                              "seconds")}


def _refine(plan: Plan, state: BuildState, log, **_) -> tuple[list[Path], dict]:
    """The capture refined to the recipe's spp (`diviewer data refine`, resumable) into ``plan.truth_dir``."""
    from diviewer.data.refine import refine

    summary = refine(plan.capture_dir, plan.truth_dir, plan.refine_spp, log=log)
    if summary["present"] != summary["planned"]:
        raise BuildInterrupted(f"refine: {summary['present']} of {summary['planned']} frames")
    return [plan.truth_dir / "manifest.json"], {"spp": plan.refine_spp, "from_spp": plan.capture.spp,
                                                **{k: summary.get(k) for k in ("present", "planned", "seconds")}}


def _filter(plan: Plan, state: BuildState, log, **_) -> tuple[list[Path], dict]:
    """The truth's indirect light filtered over each surface (`diviewer data filter-truth`, resumable) into
    ``plan.data``."""
    from diviewer.data.truth_filter import filter_dataset

    summary = filter_dataset(plan.truth_dir, plan.data, plan.truth_filter, log=log)
    if summary["present"] != summary["planned"]:
        raise BuildInterrupted(f"filter: {summary['present']} of {summary['planned']} frames")
    return [plan.data / "manifest.json"], {**plan.truth_filter.record(),
                                           **{k: summary.get(k) for k in ("present", "planned", "seconds")}}


def _check(plan: Plan, state: BuildState, log, **_) -> tuple[list[Path], dict]:
    from diviewer.data.dataset import Dataset

    ds = Dataset(plan.data)
    problems = ds.check(verify_checksum=True)
    if problems:
        raise DiviewerError(f"{len(problems)} frame(s) missing or bad (frame {problems[0].index}: "
                            f"{problems[0].problem}); run the same `diviewer build` again to render them",
                            path=plan.data)
    counts = {s: len(ds.indices(s)) for s in ("train", "val", "test")}
    if not counts["train"] or not counts["val"] or not counts["test"]:
        raise DiviewerError(f"the capture has {counts} frames per split; training needs train and val frames and "
                            f"the ladder rule test frames: capture more frames or change split_fractions",
                            path=plan.recipe.path, field="capture")
    log(f"{plan.data}: all {sum(counts.values())} frames present and sound ({counts})")
    result = {"dataset_hash": ds.hash, "frames": counts}
    shipped = plan.ship / f"{plan.scene_name}.json" if plan.ship else None
    if shipped is not None and shipped.is_file():  # rebuilding a shipped model: the same data it saw?
        before = json.loads(shipped.read_text()).get("dataset_hash")
        result["same_data_as_shipped"] = before == ds.hash
        log(f"the capture {'is' if before == ds.hash else 'is not'} the one {shipped.name} was trained on "
            f"(dataset hash {ds.hash[:16]}{'' if before == ds.hash else f', the card says {str(before)[:16]}'})")
    return [plan.data / "manifest.json"], result


def _evalset(plan: Plan, state: BuildState, log, **_) -> tuple[list[Path], dict]:
    from diviewer.evaluation.scoring import default_jobs
    from diviewer.evaluation.evalset import build_evalset

    if plan.given_evalset is not None:
        return _given_evalset(plan, log)
    from diviewer.locks import run_lock

    with run_lock(plan.evalset_dir, "evalset", option="--work"):  # as `diviewer evalset` into it
        summary = build_evalset(plan.scene, plan.evalset_dir, plan.evalset, log=log, jobs=default_jobs())
    if summary["present"] != summary["planned"]:
        raise BuildInterrupted(f"evaluation set: {summary['present']} of {summary['planned']} frames")
    return [plan.evalset_dir / "manifest.json", plan.evalset_dir / "summary.json"], {"frames": summary["present"]}


def _given_evalset(plan: Plan, log) -> tuple[list[Path], dict]:
    """An evaluation set made before (``--evalset``): of this scene file, and every frame present and sound."""
    from diviewer.builder.plan import check_evalset_scene
    from diviewer.evaluation.frames import EvalFrames
    from diviewer.evaluation.evaluate import check_frames
    from diviewer.scene.loader import load_scene

    ev = EvalFrames(plan.given_evalset)
    scene = load_scene(plan.scene)
    check_evalset_scene(ev, scene, plan.scene)  # again: the scene file may have changed since the plan was made
    check_frames(ev, partial=False, log=log)
    log(f"{plan.given_evalset}: {len(ev.frames)} frames of scene '{scene.name}', "
        f"{'compact, ' if ev.compact else ''}{ev.manifest['spp']} spp; not rendered again")
    return [plan.given_evalset / "manifest.json"], {"frames": len(ev.frames), "given": str(plan.given_evalset)}


def _train(plan: Plan, state: BuildState, log, k: int, **_) -> tuple[list[Path], dict]:
    from diviewer.locks import run_lock
    from diviewer.train.config import TrainConfig
    from diviewer.train.trainer import train

    cfg = TrainConfig(**plan.train_fields(k))
    out = plan.run_dir(k)
    _set_aside_if_begun_otherwise(cfg, out, log)
    with run_lock(out, "train", option="--work"):  # the lock `diviewer train --out` takes: one run per folder
        result = train(cfg, resume=(out / "last.ckpt").is_file(), log=log)
    n_train = min(state.data["stages"]["check"]["result"]["frames"]["train"], cfg.train_frames or math.inf)
    planned = cfg.epochs * math.ceil(n_train / cfg.batch_size)
    planned = min(planned, cfg.max_steps) if cfg.max_steps else planned
    if result["step"] < planned and not result["stopped_early"]:
        raise BuildInterrupted(f"training K={k} stopped at step {result['step']} of {planned}")
    if not (out / "best.ckpt").is_file():
        raise DiviewerError(f"training K={k} ended without a validated checkpoint", path=out / "best.ckpt")
    return [out / "best.ckpt", out / "metrics.csv"], {"step": result["step"], "best_val_ssim_tm": result["best"],
                                                      "stopped_early": result["stopped_early"]}


def _set_aside_if_begun_otherwise(cfg, run: Path, log) -> None:
    """A K whose training began under the recipe's former [train] settings (edited before any K finished,
    `BuildState.train_change`) is not resumed, which the training would refuse: the run is kept beside under another
    name, and the K trains from the start with the recipe's settings."""
    from diviewer.train.checkpoint import changed_settings, load_checkpoint

    last = run / "last.ckpt"
    diff = changed_settings(cfg, load_checkpoint(last, mmap=True)) if last.is_file() else []
    if diff:
        from diviewer.locks import run_lock

        with run_lock(run, "train", option="--work"):  # a run training there now is never moved from under it
            pass
        kept = run.with_name(f"{run.name}_before_{time.strftime('%Y%m%d_%H%M%S', time.gmtime())}")
        run.rename(kept)
        log(f"{run}: begun under other training settings ({'; '.join(diff)}); kept as {kept.name}, and trained "
            f"from the start with the recipe's")


def _export(plan: Plan, state: BuildState, log, k: int, **_) -> tuple[list[Path], dict]:
    from diviewer.evaluation.evaluate import evaluate
    from diviewer.train.export import export
    from diviewer.train.recipe import export_settings

    model = plan.model(k)
    export(plan.run_dir(k) / "best.ckpt", model, export_settings(plan.recipe), log=log)
    test = model.with_name(f"{model.stem}_test.json")
    summary = evaluate(model, plan.data, split="test", out=test, log=log)
    return [model, model.with_suffix(".json"), test], {"test_split": means_on_test_split(summary),
                                                       "frames": summary["frames"]}


def _evaluate(plan: Plan, state: BuildState, log, **_) -> tuple[list[Path], dict]:
    from diviewer.evaluation.scoring import default_jobs
    from diviewer.evaluation.evaluate import evaluate_evalset

    out = plan.work / "evalset_eval.json"
    evaluate_evalset([plan.model(k) for k in plan.ks], plan.evalset_dir, out=out, log=log, jobs=default_jobs())
    return [out], {}


def pick_within(rows: list[dict], tolerance_db: float, max_mb: float | None, recipe: Path | None = None):
    """The bench's rule over the Ks whose model file is at most ``max_mb`` MB (all where None): ``rows`` hold each
    K's ``K``, ``bytes`` and ``evalset_psnr_tm``. Returns `smallest_sufficient_k`'s pick and the Ks over the cap; an
    error naming the recipe's field where no K fits."""
    from diviewer.bench.frontier import smallest_sufficient_k

    over = sorted(r["K"] for r in rows if max_mb is not None and r["bytes"] > max_mb * 1e6)
    fits = {r["K"]: r["evalset_psnr_tm"] for r in rows if r["K"] not in over}
    if not fits:
        small = min(rows, key=lambda r: r["bytes"])
        raise DiviewerError(f"no K's model fits in {max_mb:g} MB: the smallest, K = {small['K']}, is "
                            f"{small['bytes'] / 1e6:.2f} MB", path=recipe, field="ladder.max_mb")
    return smallest_sufficient_k(fits, tolerance_db), over


def _pick(plan: Plan, state: BuildState, log, **_) -> tuple[list[Path], dict]:
    """The bench's rule: the smallest K whose tone-mapped PSNR on the evaluation set is within the recipe's
    tolerance of the best K's (`PICK_MEASURE`), of the Ks within the recipe's ``max_mb`` (`pick_within`)."""
    stages = state.data["stages"]
    ev = json.loads((plan.work / "evalset_eval.json").read_text())
    rows = []
    for k in plan.ks:
        splits = evalset_scores(ev, plan.model(k).stem)
        rows.append({"K": k, "steps": stages[f"train_k{k}"]["result"]["step"],
                     "bytes": plan.model(k).stat().st_size,
                     "test_split": stages[f"export_k{k}"]["result"]["test_split"],
                     "evalset_psnr_tm": evalset_psnr_tm(splits), "evalset": splits})
    tol, cap = plan.recipe.tolerance_db, plan.recipe.max_mb
    pick, over = pick_within(rows, tol, cap, plan.recipe.path)
    frames = sum(s["frames"] for s in rows[0]["evalset"].values())
    capped = "" if cap is None else (f", of the Ks whose model is at most {cap:g} MB (the recipe's max_mb; over it: "
                                     f"{', '.join(f'K = {k}' for k in over) or 'none'})")
    record = {"scene": plan.scene_name, "chosen_K": pick["K"], "measure": PICK_MEASURE, "max_mb": cap,
              "rule": f"smallest K whose tone-mapped PSNR over the evaluation set ({frames} frames scored: "
                      f"{stages['evalset']['result'].get('frames', '?')} rendered, window_shapes at each width; "
                      f"{ev['reference_spp']} spp) is within {tol} dB of the best K's ({pick['best_psnr']:.2f} dB)"
                      + capped,
              "recipe": plan.recipe.record(plan.overrides), "scale": plan.scale, "machine": vars(plan.machine),
              "frames": stages["check"]["result"]["frames"],
              "evalset": {"frames_per_split": plan.evalset.frames_per_split, "spp": ev["reference_spp"]},
              "rows": rows}
    out = plan.work / "ladder.json"
    imageio.write_text(out, json.dumps(record, indent=1) + "\n")
    for r in rows:
        mark = "  <- chosen" if r["K"] == pick["K"] else (
            f"  (over max_mb: {r['bytes'] / 1e6:.1f} MB)" if r["K"] in over else "")
        log(f"  K={r['K']:<4} evaluation set PSNR tm {r['evalset_psnr_tm']:.2f} dB (test split, {plan.capture.spp} "
            f"spp: {r['test_split']['neural']['psnr_tm']:.2f}){mark}")
    return [out], record


def _ship(plan: Plan, state: BuildState, log, command: str, replace_worse: bool = False, **_) -> tuple[list[Path],
                                                                                                      dict]:
    """The chosen model as SCENE.onnx with its card (the ladder and the rebuild command added, in the JSON and in
    the ONNX metadata alike), its curves, metrics and the ladder record. A model there that this build did not
    ship is scored first and replaced only where the new one scores at least as well (or ``replace_worse``), its
    files kept in WORK/replaced."""
    from diviewer.builder.checks import own_ship, replaced_model
    from diviewer.builder.replace import check_not_worse, keep_replaced
    from diviewer.outputs import SHIPPED_SUFFIXES

    if plan.ship is None:
        return [], {"to": None}
    ladder = state.data["stages"]["pick"]["result"]
    k, name = ladder["chosen_K"], plan.scene_name
    dst = plan.ship / f"{name}.onnx"
    replaced, old = None, replaced_model(plan)
    if old is not None:
        row = next(r for r in ladder["rows"] if r["K"] == k)
        replaced = check_not_worse(plan, old, k, row["evalset_psnr_tm"], replace_worse, log)
    targets = [dst, dst.with_suffix(".json"), *(plan.ship / f"{name}{s}" for s in SHIPPED_SUFFIXES)]
    kept = keep_replaced(plan, [p for p in targets if p.is_file() and not own_ship(plan, p)], log)
    if kept is not None:
        replaced = {**(replaced or {}), "kept_in": str(kept)}
    card = json.loads(plan.model(k).with_suffix(".json").read_text())
    card["ladder"] = {"chosen_K": k, "why": ladder["rule"], "file": f"{name}_ladder.json",
                      "curves": f"{name}_ladder_curves.png"}
    card["rebuild"] = command
    curves = plan.ship / card["ladder"]["curves"]
    write_ladder_curves(ladder, {r["K"]: plan.run_dir(r["K"]) for r in ladder["rows"]}, curves)
    write_model_card(plan.model(k), dst, card)
    outputs = [dst, dst.with_suffix(".json"), curves]
    for src, suffix in ((plan.run_dir(k) / "curves.png", "_curves.png"),
                        (plan.run_dir(k) / "metrics.csv", "_metrics.csv"), (plan.work / "ladder.json", "_ladder.json")):
        if src.is_file():
            with imageio.atomic_path(plan.ship / f"{name}{suffix}") as tmp:
                shutil.copyfile(src, tmp)
            outputs.append(plan.ship / f"{name}{suffix}")
    log(f"shipped K={k} as {dst} ({', '.join(p.name for p in outputs[1:])})")
    return outputs, {"to": str(plan.ship), "model": str(dst), "K": k,
                     "ladder_sha256": sha256_file(plan.work / "ladder.json"),
                     **({"replaced": replaced} if replaced else {})}


STAGES = {"capture": _capture, "refine": _refine, "filter": _filter, "check": _check, "evalset": _evalset,
          "train": _train, "export": _export, "evaluate": _evaluate, "pick": _pick, "ship": _ship}
"""Each stage kind's function: (plan, state, log, k=K of a per-K stage, command=the rebuild command) ->
(outputs whose sha256 the state records, a result record)."""
