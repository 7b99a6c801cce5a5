"""The plan of `diviewer build`: its stages, their settings, and their estimated time on this machine.

A recipe (assets/recipes/*.toml) gives the capture, the evaluation set, the training and the K ladder;
``--budget HOURS`` scales the frames and the steps together (the recipe's proportions kept) until the
estimate fits, from the costs measured on this project's machines (`diviewer.builder.costs`) scaled to the
scene as timed here or as a previous build took (`diviewer.builder.calibrate`); each stage names its source.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from diviewer.builder import costs
from diviewer.errors import DiviewerError

MIN_FRAMES = 100
"""A budget never shrinks a capture below this many frames (nor below the recipe's own, if smaller)."""
MIN_STEPS = 500
"""... nor a training below this many steps."""
MIN_EVALSET_FRAMES = 4
"""... nor an evaluation set below this many frames per split."""
RUN_ONLY = ("device", "num_workers")
"""Training fields that say where a build runs, not what it builds (neither in the recipe record nor the plan key)."""
EVALSET_SHARE = 0.2
"""Under a budget, the evaluation set takes at most this share of it (fewer frames per split)."""


@dataclass(frozen=True)
class Stage:
    """One resumable step of a build."""

    name: str
    """Its key in the state file (capture, refine, check, evalset, train_k8, export_k8, evaluate, pick, ship)."""
    title: str
    """What it does, in words."""
    seconds: float
    """Its estimated time on this machine."""
    source: str = "the constants in diviewer/builder/costs.py"
    """Where its cost comes from (`diviewer.builder.calibrate.CostBasis`)."""
    factor: float = 1.0
    """Its cost against the constants' (the measured ratio its source gives)."""


@dataclass(frozen=True)
class Plan:
    """Everything a build will do, resolved: the settings of each stage and where it writes."""

    scene: str
    """The scene as given (a shipped name or a .toml path)."""
    scene_name: str
    """The scene's own name (files are named after it)."""
    recipe: Any
    """The `diviewer.train.recipe.Recipe` it follows."""
    capture: Any
    """CaptureSettings of the capture as rendered (at the recipe's ``refine_from`` spp where it names one)."""
    evalset: Any
    """EvalSetSettings of the evaluation set."""
    train: dict[str, Any]
    """TrainConfig fields shared by every K (K, data, out, recipe are set per run)."""
    ks: tuple[int, ...]
    """The widths trained, one run each."""
    steps: int
    """Planned training steps of each run (epochs x steps per epoch, or max_steps)."""
    scale: float
    """Frames and steps relative to the recipe's (1: the recipe as written; below 1: sized to --budget)."""
    machine: costs.Machine
    """What the estimates assume."""
    work: Path
    """Folder of the data, the evaluation set, the runs, the models and the state file."""
    ship: Path | None
    """Folder the chosen model is shipped to (None: none)."""
    stages: tuple[Stage, ...]
    """The stages in order, with their estimates."""
    overrides: dict[str, Any]
    """The recipe's training fields changed (by --budget or the command line), for the recipe record."""
    given_evalset: Path | None = None
    """An evaluation set made before (``--evalset``), scored instead of rendering the recipe's; None: render it."""
    refine_spp: int | None = None
    """The spp the capture is refined to before training (`diviewer data refine`); None: trained as captured."""
    truth_filter: Any = None
    """The `diviewer.data.truth_filter.TruthFilter` run over the truth before training; None: trained on it as
    rendered."""
    evalset_counts: Any = None
    """The evaluation set's `EvalCounts`: its splits, the frames it renders and the crops it scores."""

    @property
    def seconds(self) -> float:
        return sum(s.seconds for s in self.stages)

    @property
    def capture_dir(self) -> Path:
        """Where the capture is rendered."""
        return self.work / "data"

    @property
    def truth_dir(self) -> Path:
        """The truth as rendered: the capture, or its refinement."""
        return self.capture_dir if self.refine_spp is None else self.work / f"data_{self.refine_spp}spp"

    @property
    def data(self) -> Path:
        """The dataset the trainings read: `truth_dir`, or that truth filtered (``data_Nspp_filtered``)."""
        if self.truth_filter is None:
            return self.truth_dir
        return self.work / f"data_{self.refine_spp or self.capture.spp}spp_filtered"

    @property
    def evalset_dir(self) -> Path:
        return self.given_evalset if self.given_evalset is not None else self.work / "evalset"

    def run_dir(self, k: int) -> Path:
        return self.work / f"train_k{k}"

    def model(self, k: int) -> Path:
        return self.work / "models" / f"{self.scene_name}_k{k}.onnx"

    def train_fields(self, k: int) -> dict[str, Any]:
        """The TrainConfig of the run at width ``k``."""
        rec = self.recipe.record({**self.overrides, **({"K": k} if k != self.recipe.train.get("K") else {})})
        return {**self.train, "K": k, "data": self.data, "out": self.run_dir(k), "recipe": rec}


def train_frames_of(capture, train: dict[str, Any]) -> int:
    """Frames of the train split a capture plans (its fractions), capped by the recipe's train_frames."""
    f = capture.split_fractions
    n = max(1, round(capture.frames * f[0] / sum(f)))
    return min(n, train["train_frames"]) if train.get("train_frames") else n


def planned_steps(capture, train: dict[str, Any]) -> int:
    """Steps of one run: epochs x steps per epoch (or max_steps, if smaller)."""
    from diviewer.train.config import TrainConfig

    d = {f.name: f.default for f in dataclasses.fields(TrainConfig)}
    batch, epochs = train.get("batch_size", d["batch_size"]), train.get("epochs", d["epochs"])
    steps = epochs * math.ceil(train_frames_of(capture, train) / batch)
    return min(steps, train["max_steps"]) if train.get("max_steps") else steps


def scaled(capture, train: dict[str, Any], s: float) -> tuple[Any, dict[str, Any]]:
    """Capture and training at ``s`` times the recipe's frames and steps: the step counts that mark the schedule
    (lr_decay_start, validation, saving, train_frames) scale with them, patience (in validations) does not."""
    if s >= 1.0:
        return capture, dict(train)
    steps = planned_steps(capture, train)
    cap = dataclasses.replace(capture, frames=max(1, round(capture.frames * s)))
    t = dict(train)
    if t.get("train_frames"):
        t["train_frames"] = max(1, round(t["train_frames"] * s))
    target = max(1, round(steps * s))
    per_epoch = max(1, planned_steps(cap, {**t, "epochs": 1, "max_steps": None}))
    t["epochs"] = max(1, round(target / per_epoch))
    if t.get("max_steps"):
        t["max_steps"] = target
    new = planned_steps(cap, t)
    for key in ("lr_decay_start", "val_every_steps", "save_every"):
        if t.get(key):
            t[key] = max(1, round(t[key] * new / steps))
    return cap, t


def make_plan(scene: str, recipe, work: Path, ship: Path | None = None, budget_hours: float | None = None,
              ks: tuple[int, ...] | None = None, train_overrides: dict[str, Any] | None = None,
              machine: costs.Machine | None = None, evalset_dir: Path | None = None, basis=None) -> Plan:
    """The build's plan: the recipe's stages, sized to ``budget_hours`` if given; ``evalset_dir``: score on that
    evaluation set instead of rendering the recipe's (its settings then come from its manifest); ``basis``: where
    each stage's cost comes from (`diviewer.builder.calibrate.CostBasis`; None: the constants)."""
    from diviewer.scene.loader import resolve_scene_path
    from diviewer.train.recipe import capture_settings, evalset_settings, refine_from, truth_filter

    import tomllib

    path = resolve_scene_path(scene)
    try:
        scene_name = tomllib.loads(path.read_text()).get("scene", {}).get("name", path.stem)
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise DiviewerError(f"not valid TOML: {exc}", path=path) from exc
    from diviewer.builder.checks import check_ks

    machine = machine or costs.detect_machine()
    if basis is None:
        from diviewer.builder.calibrate import CostBasis, constants_source

        basis = CostBasis(default=constants_source(scene_name))
    check_ks(ks or recipe.ks(), *(("--ks", None) if ks else ("ladder.K", recipe.path)))
    ks = tuple(ks) if ks else recipe.ks()
    train = {**recipe.train, **(train_overrides or {})}
    capture, evalset = capture_settings(recipe), evalset_settings(recipe)
    low = refine_from(recipe)
    refine_spp = None if low is None else capture.spp
    if low is not None:  # captured at the lower count, refined to the recipe's
        capture = dataclasses.replace(capture, spp=low)
    if evalset_dir is not None:
        evalset = given_evalset_settings(Path(evalset_dir), evalset, scene)
    counts = EvalCounts.of(path, evalset)
    m = (machine, basis, counts)
    s = 1.0
    if budget_hours is not None:
        if not (math.isfinite(budget_hours) and budget_hours > 0):
            raise DiviewerError(f"must be a positive number of hours, got {budget_hours}", field="--budget")
        budget = budget_hours * 3600
        if evalset_dir is None:
            evalset = _fit_evalset(evalset, scene_name, m, budget * EVALSET_SHARE)
        s = _fit_scale(capture, train, evalset, ks, scene_name, m, budget, evalset_dir, refine_spp)
        capture, train = scaled(capture, train, s)
    overrides = {k: v for k, v in train.items() if recipe.train.get(k) != v and k not in ("K", *RUN_ONLY)}
    filt = truth_filter(recipe)
    stages = _stages(scene_name, m, capture, train, evalset, ks, evalset_dir, refine_spp, filt)
    return Plan(scene=str(scene), scene_name=scene_name, recipe=recipe, capture=capture, evalset=evalset,
                train={k: v for k, v in train.items() if k != "K"}, ks=ks, steps=planned_steps(capture, train),
                scale=s, machine=machine, work=Path(work), ship=ship, stages=stages, overrides=overrides,
                given_evalset=None if evalset_dir is None else Path(evalset_dir), refine_spp=refine_spp,
                truth_filter=filt, evalset_counts=counts)


@dataclass(frozen=True)
class EvalCounts:
    """An evaluation set's frames as the plan, the render and the scoring count them: ``splits`` splits of
    ``frames_per_split`` frames are rendered (at the widest crop, ``render_width``), and each frame is scored once
    per crop of its split (the window_shapes split at each window width)."""

    splits: int
    crops: int
    """Crops scored over one frame of every split."""
    render_width: int

    @classmethod
    def of(cls, scene_path: Path, evalset) -> "EvalCounts":
        from diviewer.evaluation.evalset import plan_splits
        from diviewer.scene.loader import load_scene

        splits, _ = plan_splits(load_scene(scene_path), evalset)
        return cls(len(splits), sum(len(s["shapes"]) for s in splits.values()), evalset.render_width)

    def rendered(self, per_split: int) -> int:
        return self.splits * per_split

    def scored(self, per_split: int) -> int:
        return self.crops * per_split


def given_evalset_settings(path: Path, recipe_settings, scene: str):
    """The settings an evaluation set made before was rendered with (its manifest's), in the recipe's
    EvalSetSettings; a folder that is no evaluation set of ``scene`` (a name or a .toml path) is refused, before
    any stage runs."""
    from diviewer.evaluation.frames import EvalFrames
    from diviewer.scene.loader import load_scene

    if not (path / "manifest.json").is_file():
        raise DiviewerError("no evaluation set here (no manifest.json); make one with `diviewer evalset`, or leave "
                            "--evalset out to render the recipe's", path=path, field="--evalset")
    ev = EvalFrames(path)
    if ev.manifest.get("kind") != "evalset":
        raise DiviewerError("not an evaluation set (a training capture?)", path=path / "manifest.json", field="kind")
    check_evalset_scene(ev, load_scene(scene), scene)
    absent = ev.absent()
    if absent:
        raise DiviewerError(f"the evaluation set is incomplete: {len(ev.frames) - len(absent)} of {len(ev.frames)} "
                            f"frames present (frame {absent[0]} absent); finish it with the `diviewer evalset` command "
                            f"that started it (a build scores every frame of its set), or leave --evalset out",
                            path=path, field="--evalset")
    given = dict(ev.manifest["settings"])
    if ev.compact:  # a few frames of each split of a full set (`diviewer evalset --compact`)
        given["frames_per_split"] = ev.manifest["compact"]["frames_per_split"]
    fields = {f.name for f in dataclasses.fields(recipe_settings)}
    return dataclasses.replace(recipe_settings, **{k: v for k, v in given.items() if k in fields})


def check_evalset_scene(ev, scene, given_as: str) -> None:
    """Refuse an evaluation set (an EvalFrames) made for another scene file than ``scene`` (a loaded Scene)."""
    if ev.manifest.get("scene_hash") != scene.file_hash:
        raise DiviewerError(f"this evaluation set was made for another scene file than {given_as} (scene "
                            f"'{ev.manifest.get('scene')}'); make one of this scene with `diviewer evalset`, or leave "
                            f"--evalset out", path=ev.root / "manifest.json", field="scene_hash")


def _stages(scene: str, mbc, cap, train: dict[str, Any], ev, ks: tuple[int, ...],
            given_evalset: Path | None = None, refine_spp: int | None = None, filt=None) -> tuple[Stage, ...]:
    """The plan's stages, each costed from the constants times its basis's factor (``mbc``: the machine, the
    `CostBasis` and the `EvalCounts`)."""
    m, basis, counts = mbc
    stages = _stages_from_constants(scene, m, cap, train, ev, ks, given_evalset, refine_spp, filt, counts)
    out = []
    for s in stages:
        factor, source = basis.of(s.name)
        out.append(dataclasses.replace(s, seconds=s.seconds * factor, source=source, factor=factor))
    return tuple(out)


def _stages_from_constants(scene, m, cap, train, ev, ks, given_evalset, refine_spp, filt, counts):
    steps = planned_steps(cap, train)
    gan = train.get("gan_weight", 1.0) > 0
    batch = train.get("batch_size", 4)
    frames = counts.rendered(ev.frames_per_split)
    area = f", direct light over {cap.direct_samples}x{cap.direct_samples}" if cap.direct_samples > 1 else ""
    out = [Stage("capture", f"capture {cap.frames} frames at {cap.width}x{cap.height}, {cap.spp} spp{area}",
                 costs.capture_seconds(m.kind, scene, cap.frames, cap.width, cap.height, cap.spp,
                                       cap.direct_samples))]
    if refine_spp is not None:
        out.append(Stage("refine", f"refine the capture to {refine_spp} spp ({refine_spp - cap.spp} more a frame)",
                         costs.refine_seconds(m.kind, scene, cap.frames, cap.width, cap.height, refine_spp - cap.spp)))
    if filt is not None:
        ranged = ", a range term" if filt.range_sigma else ""
        out.append(Stage("filter", f"filter the truth's indirect light over each surface ({filt.levels} level(s)"
                                   f"{ranged})", cap.frames * costs.filter_levels(filt) * costs.FILTER_FRAME_SECONDS))
    out.append(Stage("check", "check every frame of the " + ("filtered " if filt else "") +
                     ("refined capture" if refine_spp else "capture"), 0.0))
    if given_evalset is not None:
        out.append(Stage("evalset", f"evaluation set made before: {given_evalset} ({ev.frames_per_split} frames per "
                                    f"split, {ev.spp} spp; checked, not rendered)", 0.0))
    else:
        out.append(Stage("evalset", f"evaluation set: {counts.splits} splits x {ev.frames_per_split} frames = {frames}"
                                    f" rendered at {counts.render_width}x{ev.height}, {counts.scored(ev.frames_per_split)}"
                                    f" crops scored; {ev.spp} spp twice, ladder {'/'.join(map(str, ev.ladder))}",
                         costs.evalset_seconds(m.kind, scene, frames, counts.render_width, ev.height, ev.spp,
                                               tuple(ev.ladder))))
    for k in ks:
        out.append(Stage(f"train_k{k}", f"train K={k}: {steps} steps of batch {batch}",
                         steps * costs.train_step_seconds(m.kind, k, batch, cap.width, cap.height, gan,
                                                          train.get("aspect_crops"))))
        out.append(Stage(f"export_k{k}", f"export K={k} and score it on the capture's test split",
                         costs.EXPORT_EVAL_ALLOWANCE))
    out += [Stage("evaluate", "score every K on the evaluation set", 0.0),
            Stage("pick", "pick the smallest sufficient K (the bench's rule)", 0.0),
            Stage("ship", "ship the chosen model with its card, curves and ladder", 0.0)]
    return tuple(out)


def _total(cap, train, ev, ks, scene, m, given_evalset=None, refine_spp=None) -> float:
    return sum(s.seconds for s in _stages(scene, m, cap, train, ev, ks, given_evalset, refine_spp))


def _fit_evalset(ev, scene: str, mbc, seconds: float):
    """Fewer evaluation frames per split until they fit in ``seconds`` (never below MIN_EVALSET_FRAMES)."""
    m, basis, counts = mbc
    n = ev.frames_per_split
    per = costs.evalset_seconds(m.kind, scene, counts.splits, counts.render_width, ev.height, ev.spp,
                                tuple(ev.ladder)) * basis.of("evalset")[0]
    fit = max(min(n, MIN_EVALSET_FRAMES), min(n, int(seconds // per)))
    return dataclasses.replace(ev, frames_per_split=fit)


def _fit_scale(cap, train, ev, ks, scene, m, budget: float, given_evalset: Path | None = None,
               refine_spp: int | None = None) -> float:
    """The largest s <= 1 whose plan fits ``budget`` seconds; an error where even the smallest plan does not."""
    steps = planned_steps(cap, train)
    s_min = min(1.0, max(MIN_FRAMES / cap.frames, MIN_STEPS / max(steps, 1)))
    if _total(cap, train, ev, ks, scene, m, given_evalset, refine_spp) <= budget:
        return 1.0
    smallest = _total(*scaled(cap, train, s_min), ev, ks, scene, m, given_evalset, refine_spp)
    if smallest > budget:
        raise DiviewerError(f"{budget / 3600:.2f} h is below the smallest plan this recipe allows on this machine "
                            f"({smallest / 3600:.2f} h at {MIN_FRAMES} frames and {MIN_STEPS} steps per K; the "
                            f"capture costed from {m[1].of('capture')[1]}); give "
                            f"more hours, fewer K (--ks) or a lighter recipe", field="--budget")
    lo, hi = s_min, 1.0
    for _ in range(40):
        mid = (lo + hi) / 2
        fits = _total(*scaled(cap, train, mid), ev, ks, scene, m, given_evalset, refine_spp) <= budget
        lo, hi = (mid, hi) if fits else (lo, mid)
    return lo


def describe(plan: Plan, done: set[str] = frozenset(), left_here: dict[str, float] | None = None) -> list[str]:
    """The plan for people: what each stage does and how long it should take on this machine (``done``: stages a
    build in the work folder has finished, whose outputs still match; they are skipped; ``left_here``: the seconds
    left of stages under way at this machine's measured pace, `diviewer.builder.pace`)."""
    r = plan.recipe
    lines = [f"build {plan.scene_name} ({plan.scene}) with recipe {r.name} ({r.path}, sha256 {r.sha256[:12]})",
             f"machine: {plan.machine.kind}, {plan.machine.cpus} CPU cores; {plan.machine.why}",
             f"work folder: {plan.work}; ship to: {plan.ship if plan.ship else 'nowhere (no --ship)'}"]
    if plan.scale < 1.0:
        lines.append(f"sized to the budget: {plan.scale:.1%} of the recipe's frames and steps "
                     f"({plan.capture.frames} frames, {plan.steps} steps per K, "
                     f"{plan.evalset.frames_per_split} evaluation frames per split)")
    changed = ", ".join(f"{k}={v}" for k, v in sorted(plan.overrides.items()))
    if changed:
        lines.append(f"training fields changed from the recipe: {changed}")
    lines.append(f"K ladder {', '.join(map(str, plan.ks))}; the smallest K within {r.tolerance_db} dB of the best "
                 f"(tone-mapped PSNR on the evaluation set's truth) is shipped"
                 + (f", of those whose model is at most {r.max_mb:g} MB" if r.max_mb is not None else ""))
    for i, s in enumerate(plan.stages, 1):
        lines.append(f"  {i:2d}. {s.name:<12} {'done' if s.name in done else hms(s.seconds):>9}  {s.title}")
    left = sum(s.seconds for s in plan.stages if s.name not in done)
    lines.append(f"estimated total: {hms(plan.seconds)}" + (f", {hms(left)} left (stages done in {plan.work} are "
                                                             f"skipped)" if done else ""))
    by_source: dict[str, list[str]] = {}
    for s in plan.stages:
        if s.seconds > 0:
            by_source.setdefault(s.source, []).append(s.name)
    for source, names in by_source.items():
        lines.append(f"  costs of {', '.join(names)}: {source}")
    ev = next((s for s in plan.stages if s.name == "evalset"), None)
    if ev is not None and ev.seconds > 0 and plan.seconds > 0:
        share = ev.seconds / plan.seconds
        over = (f", above the {EVALSET_SHARE:.0%} a budget gives it: {MIN_EVALSET_FRAMES} frames per split is the "
                f"fewest a build renders" if plan.evalset.frames_per_split <= MIN_EVALSET_FRAMES
                and share > EVALSET_SHARE + 0.005 else "")
        lines.append(f"  the evaluation set is {share:.0%} of the estimate{over}")
    under_way = [s for s in plan.stages if s.name not in done and s.name in (left_here or {})]
    if under_way:
        here = sum(left_here.get(s.name, s.seconds) for s in plan.stages if s.name not in done)
        lines.append(f"left with {', '.join(s.name for s in under_way)} at this machine's measured pace (below) and "
                     f"the rest as estimated: ~{hms(here)}")
    return lines


def hms(seconds: float) -> str:
    """A duration for people: '1 h 05 min', '12 min' or '40 s'."""
    m = round(seconds / 60)
    return f"{m // 60} h {m % 60:02d} min" if m >= 60 else (f"{m} min" if m else f"{seconds:.0f} s")
