"""`diviewer evalset`: the fixed evaluation set of a scene, rendered once and reused by every comparison.

An evaluation set is a dataset in the capture format (diviewer/data: manifest.json, frames/*.npy with
checksummed sidecars, resumable and atomic), with ``"kind": "evalset"`` in its manifest and more
channels per frame:

- the GL inputs (depth, normal, albedo, direct) and the ground truth ``pt`` (full GI) and ``pt_direct``
  (path length 2) at ``spp`` (>= 1024), as in a training capture;
- ``pt_b``: the same frame at the same spp with a second seed, whose distance to ``pt`` is the noise
  floor (no method can be judged closer to the truth than the truth is to itself);
- ``pt_spp1``, ``pt_spp4``, ... : the path tracer at each sample count of the ladder, each with its own
  seed, so a method's error can be read as the sample count at which Mitsuba makes the same error.

Two splits: ``unseen_configs`` (configurations drawn like training ones, training meshes) and
``unseen_objects`` (the sampler's test split: held-out meshes, unseen camera stretches). Seeds come
from a stream of their own (EVAL_STREAM), never from a capture's ``SeedSequence([seed, i])``, so no
evaluation frame is a training frame. The tone map's exposure is fitted once on the GL direct light
of all planned frames and stored in the manifest: every model is scored with the same tone map.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from diviewer.data.dataset import CHANNELS, FORMAT, FORMAT_VERSION, read_manifest
from diviewer.data.evalset_format import EVAL_SPLITS, KIND, is_evalset, load_evalset  # noqa: F401 (re-exported)
from diviewer.errors import DiviewerError
from diviewer.provenance import versions
from diviewer.scene import FrameConfig, Scene, load_scene, sample_config

SAMPLER_SPLIT = {"unseen_configs": "train", "unseen_objects": "test"}
"""Which split of the scene's sampler each evaluation split draws from (with seeds no capture uses)."""
LADDER = (1, 4, 16, 64, 256)
EVAL_STREAM = 0xE7A15E7
"""First word of every evaluation seed: captures seed with SeedSequence([capture seed, frame index])."""
SECOND_SEED = "pt_b"
"""Channel of the second full render (noise floor)."""


def ladder_channel(spp: int) -> str:
    return f"pt_spp{int(spp)}"


@dataclass(frozen=True)
class EvalSetSettings:
    """What an evaluation set renders; recorded in its manifest."""

    frames_per_split: int = 24
    """Frames in each of the two splits."""
    width: int = 128
    height: int = 128
    spp: int = 1024
    """Samples per pixel of the ground truth (and of its second-seed copy)."""
    ladder: tuple[int, ...] = field(default=LADDER)
    """Lower sample counts rendered for the equivalent sample count, increasing."""
    max_depth: int = 16
    """Path length limit of the full renders (the direct-only one uses 2)."""
    seed: int = 0
    """Which evaluation set of the stream (0: the one every comparison uses)."""
    dtype: str = "float32"
    """Frame storage type; float32 keeps the 1024-spp noise floor free of float16 rounding."""
    thumbs: int = 2
    """PNG thumbnails for the first frames of each split."""

    def check(self) -> None:
        if self.frames_per_split < 1 or self.width < 16 or self.height < 16:
            raise DiviewerError("an evaluation set needs >= 1 frame per split and >= 16x16 pixels "
                                "(SSIM's window is 11 pixels)", field="--frames-per-split/--res")
        if self.spp < 1 or self.max_depth < 2:
            raise DiviewerError("spp must be >= 1 and max_depth >= 2", field="--spp")
        lad = list(self.ladder)
        if not lad or lad != sorted(set(lad)) or lad[0] < 1 or lad[-1] >= self.spp:
            raise DiviewerError(f"the ladder must be increasing sample counts below --spp {self.spp}, got {lad}",
                                field="--ladder")
        if self.dtype not in ("float16", "float32"):
            raise DiviewerError(f"dtype must be float16 or float32, got {self.dtype}", field="--dtype")


def channels(settings: EvalSetSettings) -> tuple[tuple[str, int], ...]:
    """The capture's channels, then the second-seed render, then the ladder."""
    return CHANNELS + ((SECOND_SEED, 3),) + tuple((ladder_channel(n), 3) for n in settings.ladder)


def _seeds(settings: EvalSetSettings, split_index: int, i: int) -> dict:
    seq = np.random.SeedSequence([EVAL_STREAM, settings.seed, split_index, i])
    state = seq.generate_state(3 + len(settings.ladder))
    s = [int(x & 0x7FFFFFFF) for x in state]
    return {"config": s[0], "reference": s[1], "second": s[2], "ladder": s[3:]}


def plan_evalset(scene: Scene, settings: EvalSetSettings) -> list[dict]:
    """Every frame's index, split, seeds and configuration: a pure function of scene and settings."""
    plan = []
    for k, split in enumerate(EVAL_SPLITS):
        for i in range(settings.frames_per_split):
            seeds = _seeds(settings, k, i)
            config = sample_config(scene, seeds["config"], SAMPLER_SPLIT[split])
            plan.append({"index": k * settings.frames_per_split + i, "split": split, "seed": seeds["config"],
                         "sampler_split": SAMPLER_SPLIT[split], "pt_seeds": seeds, "config": config.to_dict()})
    return plan


def build_manifest(scene: Scene, settings: EvalSetSettings, plan: list[dict], exposure: float,
                   ladder_spp: list[int]) -> dict:
    from diviewer.gl.renderer import RenderSettings

    return {
        "format": FORMAT, "format_version": FORMAT_VERSION, "kind": KIND,
        "scene": scene.name, "scene_hash": scene.file_hash,
        "scene_file": str(scene.path) if scene.path else None,
        "scene_toml": scene.path.read_text() if scene.path else None,
        "resolution": [settings.width, settings.height],
        "channels": [list(c) for c in channels(settings)],
        "dtype": settings.dtype, "gt": "pt", "spp": settings.spp, "max_depth": settings.max_depth,
        "seed": settings.seed, "frames": len(plan), "split_fractions": [0.5, 0.5],
        "render_settings": asdict(RenderSettings()),
        "settings": asdict(settings),
        "evalset": {
            "splits": dict(SAMPLER_SPLIT), "seed_stream": EVAL_STREAM, "second_seed_channel": SECOND_SEED,
            "ladder_spp": ladder_spp, "ladder_channels": [ladder_channel(n) for n in settings.ladder],
            "tonemap": {"exposure": exposure, "curve": "diviewer.metrics.tonemap (Reinhard at the exposure, "
                        "gamma 2.2)", "fitted_on": "GL direct light of all planned frames (encoding.fit_exposure)"},
        },
        "versions": versions(),
        "frame_list": plan,
    }


class EvalTruth:
    """Mitsuba renders of one evaluation frame: reference, direct, second seed, and the ladder."""

    def __init__(self, scene: Scene, settings: EvalSetSettings):
        from diviewer.reference import mitsuba as ref

        self.ref, self.scene, self.settings = ref, scene, settings
        self.variant = ref.select_variant()

    def __call__(self, config: FrameConfig, entry: dict) -> dict[str, np.ndarray]:
        s, seeds = self.settings, entry["pt_seeds"]
        frame = self.ref.load_frame(self.scene, config, s.width, s.height)
        out = {"pt": frame.full(s.spp, seeds["reference"], s.max_depth),
               "pt_direct": frame.direct(s.spp, seeds["reference"]),  # same seed as in a capture
               SECOND_SEED: frame.full(s.spp, seeds["second"], s.max_depth)}
        for n, seed in zip(s.ladder, seeds["ladder"]):
            out[ladder_channel(n)] = frame.full(n, seed, s.max_depth)
        return out


def _fit_exposure(ctx, scene: Scene, plan: list[dict], settings: EvalSetSettings) -> float:
    """The tone map's exposure from the GL direct light of every planned frame (cheap: no path tracing)."""
    from diviewer.encoding import fit_exposure
    from diviewer.gl.renderer import Renderer
    from diviewer.scene.loader import config_from_dict

    renderer = Renderer(ctx, scene, settings.width, settings.height)
    try:
        direct = [renderer.frame(config_from_dict(scene, f["config"]))["direct"] for f in plan]
    finally:
        renderer.release()
    return float(fit_exposure(direct))


def build_evalset(scene_name: str | Path, out: Path, settings: EvalSetSettings = EvalSetSettings(),
                  log=print) -> dict:
    """Render the frames of the evaluation set that are not complete yet (resumable); returns a summary.

    When every frame is present, the noise floor and Mitsuba's own error at each ladder count are
    scored per split (diviewer.evaluate) and written to ``summary.json``.
    """
    from diviewer.data.capture import _clean_stale, _render_frames_gl, open_or_create
    from diviewer.gl.context import describe, headless_context
    from diviewer.render import check_reference

    settings.check()
    check_reference("pt")  # a missing extra fails before any GL work
    scene = load_scene(scene_name)
    truth = EvalTruth(scene, settings)
    plan = plan_evalset(scene, settings)
    ladder_spp = [truth.ref.effective_spp(n) for n in settings.ladder]
    out = Path(out)
    t0 = time.perf_counter()
    with headless_context() as ctx:
        if (out / "manifest.json").is_file():
            existing = read_manifest(out)
            if existing.get("kind") != KIND:
                raise DiviewerError("a dataset that is not an evaluation set is already there; use another --out",
                                    path=out)
            exposure = float(existing["evalset"]["tonemap"]["exposure"])
        else:
            exposure = _fit_exposure(ctx, scene, plan, settings)
        ds = open_or_create(out, build_manifest(scene, settings, plan, exposure, ladder_spp))
        _clean_stale(ds, {f["index"] for f in plan})
        todo = [f for f in ds.frames if ds.check_frame(f["index"]) is not None]
        per_frame = settings.spp * 2 + sum(settings.ladder)
        log(f"evalset {scene.name}: {len(plan) - len(todo)} of {len(plan)} frames done, {len(todo)} to render at "
            f"{settings.width}x{settings.height} ({settings.spp} spp twice + direct + ladder "
            f"{'/'.join(map(str, settings.ladder))}: {per_frame} full samples per pixel per frame, {truth.variant})")
        if todo:
            _render_frames_gl(ctx, scene, ds, todo, settings, truth, describe(ctx), log, label="evalset")
    summary = {"planned": len(plan), "present": len(ds.indices()), "seconds": round(time.perf_counter() - t0, 1)}
    if summary["present"] == len(plan):
        from diviewer.evaluate import evaluate_evalset

        result = evaluate_evalset([], out, log=log, out=out / "summary.json")
        summary["noise_floor"] = {s: r["methods"]["noise_floor"] for s, r in result["splits"].items()}
    log(f"done: {summary['present']}/{summary['planned']} frames in {out}, {summary['seconds']:.0f} s")
    return summary


def configs_apart(frames: list[dict], others: list[dict]) -> bool:
    """True when no configuration of one frame list (an evaluation set's) appears in the other (a capture's)."""
    mine = {json.dumps(f["config"], sort_keys=True) for f in frames}
    return not any(json.dumps(f["config"], sort_keys=True) in mine for f in others)
