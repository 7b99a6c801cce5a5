"""What a build's work folder says of its progress before the build has recorded it, for ``diviewer build`` (its
plan's lines, a dry run's too): a capture already complete there (and whether a run takes it: `Pace.done`), and
the pace of a capture, refinement or training under way on this machine (and of a training not begun, from one
that has), beside the plan's estimates from costs measured elsewhere."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Callable, NamedTuple

from diviewer.builder.plan import Plan, hms
from diviewer.errors import DiviewerError


def missing_link(plan: Plan) -> str | None:
    """Why a run refuses the work folder's capture folder before looking in it: a link to a folder that is not there
    (a refined set another build has yet to make, linked ahead of it), which a capture would
    otherwise fill through the link, at the recipe's ``refine_from`` spp, for hours; None where it is not one."""
    where = plan.capture_dir
    if not where.is_symlink() or where.exists():
        return None
    return (f"links to {where.readlink()}, which is not there: a run refuses it (make that set first, or remove the "
            f"link to capture in {plan.work})")


def capture_refusal(plan: Plan) -> str | None:
    """Why a run would refuse the dataset in the work folder's capture folder for the recipe's capture (the identity
    fields it differs in, as `diviewer.data.capture.settings_differ` reads them, or its manifest's fault), or None
    where it is that capture."""
    from diviewer.data.capture import settings_differ

    try:
        diff = settings_differ(plan.scene, plan.capture_dir, plan.capture)
    except DiviewerError as exc:
        return str(exc)
    return f"it is not the recipe's capture (differs in: {', '.join(diff)})" if diff else None


class Pace(NamedTuple):
    """What a stage under way says of this machine's pace: a line for people, and the stage's seconds left at that
    pace (None where it has nothing left to time: a complete capture, taken or refused); ``done``: a capture complete
    in the work folder with the recipe's settings though no build has recorded it (a run renders none, so a dry run
    counts it done)."""

    stage: str
    line: str
    left: float | None = None
    done: bool = False


def measured_pace(plan: Plan) -> list[Pace]:
    """What the work folder's capture, refinement and trainings under way say of this machine's pace, and their time
    left at it, beside the plan's estimates from the costs measured elsewhere: one each (none before they start or
    once they are done); a K not begun, at the pace of the K measured here nearest to it (`scaled_training_pace`)."""
    paces = [capture_pace(plan), refine_pace(plan)]
    stages = {s.name: s for s in plan.stages}
    rows = {k: last_row(plan.run_dir(k) / "metrics.csv") for k in plan.ks}
    measured = {k: (*row, stages[f"train_k{k}"].seconds) for k, row in rows.items()
                if row is not None and row[0] >= MIN_PACE_STEPS}
    for k in plan.ks:
        if rows[k] is not None:
            paces.append(_pace_under_way(rows[k], k, plan.steps, stages[f"train_k{k}"].seconds))
        else:
            paces.append(scaled_training_pace(k, plan.steps, stages[f"train_k{k}"].seconds, measured))
    return [p for p in paces if p]


def last_row(metrics: Path) -> tuple[int, float] | None:
    """A training run's last step and its cumulative seconds (resumes included) from its metrics.csv; None before
    its first row (no file, a header alone, a row being written)."""
    import csv

    try:
        with open(metrics, newline="") as f:
            rows = [r for r in csv.DictReader(f) if r.get("step") and r.get("seconds")]
        step, seconds = int(rows[-1]["step"]), float(rows[-1]["seconds"])
    except (OSError, IndexError, ValueError, KeyError):
        return None
    return (step, seconds) if step > 0 else None


def training_pace(metrics: Path, k: int, planned_steps: int, planned_seconds: float) -> Pace | None:
    """A training run's pace so far from its metrics.csv (the last row's step and its cumulative seconds, resumes
    included), and its time left at that pace; None before its first row or once it is done."""
    return _pace_under_way(last_row(metrics), k, planned_steps, planned_seconds)


def _pace_under_way(row: tuple[int, float] | None, k: int, planned_steps: int, planned_seconds: float) -> Pace | None:
    if row is None or row[0] >= planned_steps:
        return None
    step, seconds = row
    per = seconds / step
    left = (planned_steps - step) * per
    return Pace(f"train_k{k}", f"train K={k} so far: step {step} of {planned_steps}, {per:.2f} s a step here "
                f"(validations included); the rest take ~{hms(left)} at that pace (the plan assumes "
                f"{planned_seconds / planned_steps:.2f} s)", left)


MIN_PACE_STEPS = 200
"""A run's pace stands for the K not begun once it has this many steps (its first rows carry the start's costs)."""


def scaled_training_pace(k: int, planned_steps: int, planned_seconds: float,
                         measured: dict[int, tuple[int, float, float]]) -> Pace | None:
    """A K not begun, at this machine's pace: the seconds a step of the measured K nearest to it in width (``measured``:
    K -> its last step, cumulative seconds and the plan's seconds for it), times the plan's ratio of the two Ks'
    costs; None where no K is measured. The plan's costs were measured on other machines (a 2-core CPU's one torch
    thread, an H100 shared with other jobs): the ratio between two widths carries over better than either."""
    import math

    if not measured:
        return None
    m = min(measured, key=lambda j: (abs(math.log(k / j)), j))
    step, seconds, planned_m = measured[m]
    ratio = planned_seconds / planned_m
    per = seconds / step * ratio
    left = planned_steps * per
    return Pace(f"train_k{k}", f"train K={k} not begun: ~{per:.2f} s a step here, K={m}'s {seconds / step:.2f} s "
                f"measured over {step} steps times the plan's cost ratio of the two ({ratio:.2f}); ~{hms(left)} at that "
                f"pace (the plan assumes {planned_seconds / planned_steps:.2f} s)", left)


PACE_FRAMES = 200
"""The capture's pace is the median of its last this many frames (the machine's pace now, not a day's mean)."""


def frame_seconds(folder: Path, seconds_of: Callable[[dict], float]) -> tuple[int, list[float]]:
    """A dataset folder's frame count and each frame's seconds as its sidecar records them (``seconds_of``); frames
    being written, or of an older format, are counted and not timed."""
    frames = sorted((folder / "frames").glob("*.json")) if (folder / "manifest.json").is_file() else []
    seconds = []
    for f in frames:
        try:
            seconds.append(float(seconds_of(json.loads(f.read_text()))))
        except (ValueError, KeyError, TypeError, OSError):
            continue  # a frame being written, or one of an older format: the others tell the pace
    return len(frames), seconds


def _manifest(folder: Path) -> dict:
    """A dataset folder's manifest as read, or {} (none, or unreadable: the stages themselves say so)."""
    try:
        return json.loads((folder / "manifest.json").read_text())
    except (OSError, ValueError):
        return {}


def capture_pace(plan: Plan) -> Pace | None:
    """What the frames already captured in the work folder say of this machine's pace (each frame's sidecar records
    its GL and path-tracing seconds), and the capture's time left at that pace, beside the plan's estimate from the
    measured costs (another machine's); once every frame is there, whether a run takes it (`capture_refusal`) and
    renders none; None where no frame is there. A refined dataset there (`diviewer.data.capture.refined_stand_in`)
    is nothing to render: whether it is complete, and taken."""
    where = plan.capture_dir
    if (why := missing_link(plan)) is not None:
        return Pace("capture", f"capture: {where} {why}")
    count, seconds = frame_seconds(where, lambda info: float(info["seconds"]["gl"]) + float(info["seconds"]["gt"]))
    refined = _manifest(where).get("refined")
    left = plan.capture.frames - count
    refusal = capture_refusal(plan) if count and left <= 0 else None
    taken = bool(count) and left <= 0 and refusal is None
    if isinstance(refined, dict) and count:
        return Pace("capture", f"capture: {where} is the capture at {refined.get('from_spp')} spp refined to "
                    f"{plan.capture.spp}, " + (
                        f"{count} of {plan.capture.frames} frames: a run refuses it until the rest are refined"
                        if left > 0 else f"complete, but a run refuses it: {refusal}" if refusal else
                        "complete: a run takes it for the capture and renders none"), done=taken)
    if count and left <= 0:
        return Pace("capture", f"capture: all {plan.capture.frames} frames already in {where}; "
                    + (f"but a run refuses it: {refusal}" if refusal else "its settings are the recipe's: a run "
                       "renders none"), done=taken)
    if not seconds:
        return None
    planned = plan.stages[0].seconds / plan.capture.frames
    per, words = _pace(seconds, left, "median of GL + path tracing, ")
    return Pace("capture", f"capture so far: {count} of {plan.capture.frames} frames in {where}, {words} (the plan "
                f"assumes {planned:.1f} s, from {plan.stages[0].source})", left * per)


def _pace(seconds: list[float], left: int, what: str = "median, ") -> tuple[float, str]:
    """A frame's time here (the median of the last ``PACE_FRAMES``), and it and the ``left`` frames' time at it in
    words."""
    import statistics

    per = statistics.median(seconds[-PACE_FRAMES:])
    return per, (f"{per:.1f} s a frame here ({what}the last {min(len(seconds), PACE_FRAMES)} frames); the {left} "
                 f"left take ~{hms(left * per)} at that pace")


def refine_pace(plan: Plan) -> Pace | None:
    """As `capture_pace`, for the refinement of the capture (each refined frame's sidecar records its seconds);
    before its first frame, the capture's own path tracing here scaled to the refinement's samples
    (`_capture_sample_seconds`); None without a ``refine`` stage, without either, or once it is complete."""
    stage = next((s for s in plan.stages if s.name == "refine"), None)
    if stage is None:
        return None
    count, seconds = frame_seconds(plan.truth_dir, lambda info: info["refined"]["seconds"])
    left = plan.capture.frames - count
    assumed = f"the plan assumes {stage.seconds / plan.capture.frames:.1f} s"
    if left <= 0:
        return None
    if not seconds:
        sample = _capture_sample_seconds(plan)
        if sample is None:
            return None
        extra = plan.refine_spp - plan.capture.spp
        per = sample * extra
        return Pace("refine", f"refine not begun: ~{per:.1f} s a frame here, the capture's path tracing on this "
                    f"machine (median of its last {PACE_FRAMES} frames) per sample, times the {extra} samples a "
                    f"frame to add; the {left} frames take "
                    f"~{hms(left * per)} at that pace ({assumed})", left * per)
    per, words = _pace(seconds, left)
    return Pace("refine", f"refine so far: {count} of {plan.capture.frames} frames in {plan.truth_dir}, {words} "
                f"({assumed})", left * per)


def _capture_sample_seconds(plan: Plan) -> float | None:
    """This machine's path-tracing seconds per sample a frame from the capture's frames (the median of the last
    ``PACE_FRAMES``): a frame's ``gt`` seconds over the capture's spp, or, in a capture that is itself a
    refinement (its sidecars' ``refined``), the refinement's seconds over its samples. Frames path traced with
    another kind of Mitsuba variant (a CUDA device's against this CPU) do not tell this machine's pace; None where
    none do."""
    import statistics

    cuda = plan.machine.kind == "cuda"

    def per_sample(info: dict) -> float:  # a ValueError or KeyError leaves the frame out (`frame_seconds`)
        r = info["refined"] if "refined" in info else None  # (a sidecar that is no object: a TypeError below)
        variant, seconds, spp = ((r["variant"], r["seconds"], r["extra_spp"]) if r else
                                 (info["variant"], info["seconds"]["gt"], plan.capture.spp))
        if variant.startswith("cuda") != cuda:
            raise ValueError(f"path traced with {variant}")
        return float(seconds) / int(spp)

    _, seconds = frame_seconds(plan.capture_dir, per_sample)
    return statistics.median(seconds[-PACE_FRAMES:]) if seconds else None
