"""`diviewer evalset`: the fixed evaluation set of a scene, rendered once and reused by every comparison.

An evaluation set is a dataset in the capture format (diviewer/data: manifest.json, frames/*.npy with
checksummed sidecars, resumable and atomic), with ``"kind": "evalset"`` in its manifest and more
channels per frame:

- the GL inputs (depth, normal, albedo, direct) and the ground truth ``pt`` (full GI) and ``pt_direct``
  (path length 2) at ``spp`` (>= 1024), as in a training capture;
- ``pt_b``: the same frame at the same spp with a second seed, whose distance to ``pt`` is the noise
  floor (no method can be judged closer to the truth than the truth is to itself);
- ``pt_spp1``, ``pt_spp4``, ... : the path tracer at each sample count of the ladder, each with its own
  seed, so a method's error can be read as the sample count at which Mitsuba makes the same error;
- ``object`` (scenes with movable objects): 1 where a movable object (``[ranges.objects]``) is the
  visible surface, from a second GL render of the frame with only those objects whose depth matches the
  full frame's (the G-buffer has no object id). The region metrics (diviewer.regions) read it.

Splits (each drawn from a seed stream of its own, EVAL_STREAM, never a capture's
``SeedSequence([seed, i])``, so no evaluation frame is a training frame):

- ``unseen_configs``: lights and objects drawn like training ones (training meshes), at the scene's
  camera (the scene file's camera for a scene with a free-camera region: the paper's protocol; the
  training stretches of a camera path);
- ``unseen_objects``: the sampler's held-out meshes, at the same camera (streams 0 and 1: the frames of
  the evaluation sets before moved_camera and window_shapes existed, so their figures stay comparable);
- ``moved_camera``: cameras in the held-out regions of a free camera (``test_regions``) or on the unseen
  stretches of a camera path, with training meshes (a scene that holds out no meshes draws it from
  stream 1, the frames its ``unseen_objects`` split had);
- ``window_shapes``: the configurations of unseen_configs' kind, scored at each window shape
  (4:3 and 16:9 at the model's row count unless set), each frame at every shape.

A split a scene cannot have (no held-out meshes, no camera ranges) is left out and named in the
manifest's ``evalset.left_out`` with the reason; eval prints it.

Shapes: every frame is rendered once at the widest shape (``render_width`` x ``height``) and each split
is scored on centred crops (``crop``): at the same vertical field of view a centred crop of a wider
render is the narrower frame (the projection's pixel centres coincide when the widths differ by an even
number of pixels, which ``check`` enforces; shadow maps fit the scene's bounds, not the view): GL buffers
agree to rounding, except that a pixel centre on the edge between two surfaces at the same depth (a wall's
corner) may rasterise to the other one (< 1 % of a 32-pixel frame's pixels, fewer at 128), and the path
tracer's frames differ only in their noise.
One stored resolution keeps the dataset format, its checks and resume unchanged.

The tone map's exposure is fitted once, on the GL direct light of the square crops of streams 0 and 1
(diviewer.contract.encoding.fit_exposure: deterministic), and stored in the manifest: every model and every
split is scored with the same tone map, the scene's, never a model's.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from diviewer.data.dataset import CHANNELS, FORMAT, FORMAT_VERSION, read_manifest
from diviewer.data.evalset_format import EVAL_SPLITS, KIND, is_evalset, load_evalset  # noqa: F401 (re-exported)
from diviewer.errors import DiviewerError
from diviewer.evaluation.frames import crop
from diviewer.provenance import versions
from diviewer.scene import FrameConfig, Scene, load_scene, sample_config

STREAM = {"unseen_configs": 0, "unseen_objects": 1, "moved_camera": 2, "window_shapes": 3}
"""Seed stream of each split (moved_camera takes 1 where unseen_objects is left out)."""
SAMPLER_SPLIT = {"unseen_configs": "train", "unseen_objects": "test", "moved_camera": "test",
                 "window_shapes": "train"}
"""Which split of the scene's sampler each evaluation split draws from (with seeds no capture uses)."""
WINDOW_ASPECTS = ((4, 3), (16, 9))
"""Window shapes of the window_shapes split (width:height) at the model's row count."""
LADDER = (1, 4, 16, 64, 256)
EVAL_STREAM = 0xE7A15E7
"""First word of every evaluation seed: captures seed with SeedSequence([capture seed, frame index])."""
SECOND_SEED = "pt_b"
"""Channel of the second full render (noise floor)."""
OBJECT_CHANNEL = "object"
"""Channel of the movable objects' mask (1 where one is the visible surface)."""


def ladder_channel(spp: int) -> str:
    return f"pt_spp{int(spp)}"


def aspect_width(height: int, aspect: tuple[int, int]) -> int:
    """The even width nearest to ``height`` x aspect (even: centred crops start on a whole pixel)."""
    return max(2, 2 * int(round(height * aspect[0] / aspect[1] / 2.0)))


@dataclass(frozen=True)
class EvalSetSettings:
    """What an evaluation set renders; recorded in its manifest."""

    frames_per_split: int = 24
    """Frames in each split."""
    width: int = 128
    """Width of the model's frame (the square splits' crop)."""
    height: int = 128
    """Rows of every frame (the model's row count)."""
    window_widths: tuple[int, ...] | None = None
    """Widths the window_shapes split is scored at; None: 4:3 and 16:9 at ``height`` (``WINDOW_ASPECTS``)."""
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

    @property
    def windows(self) -> tuple[int, ...]:
        if self.window_widths is not None:
            return tuple(int(w) for w in self.window_widths)
        return tuple(aspect_width(self.height, a) for a in WINDOW_ASPECTS)

    @property
    def render_width(self) -> int:
        """Width every frame is rendered at: the widest crop."""
        return max(self.width, *self.windows)

    def check(self) -> None:
        if self.frames_per_split < 1 or self.width < 16 or self.height < 16:
            raise DiviewerError("an evaluation set needs >= 1 frame per split and >= 16x16 pixels "
                                "(SSIM's window is 11 pixels)", field="--frames-per-split/--res")
        if any(w < 16 for w in self.windows) or len(set(self.windows)) != len(self.windows):
            raise DiviewerError(f"window widths must be distinct and >= 16, got {list(self.windows)}",
                                field="--window-widths")
        odd = [w for w in (self.width, *self.windows) if (self.render_width - w) % 2]
        if odd:
            raise DiviewerError(f"widths {odd} differ from the widest ({self.render_width}) by an odd number of "
                                f"pixels: a centred crop must start on a whole pixel; use even widths",
                                field="--res/--window-widths")
        if self.spp < 1 or self.max_depth < 2:
            raise DiviewerError("spp must be >= 1 and max_depth >= 2", field="--spp")
        lad = list(self.ladder)
        if not lad or lad != sorted(set(lad)) or lad[0] < 1 or lad[-1] >= self.spp:
            raise DiviewerError(f"the ladder must be increasing sample counts below --spp {self.spp}, got {lad}",
                                field="--ladder")
        if self.dtype not in ("float16", "float32"):
            raise DiviewerError(f"dtype must be float16 or float32, got {self.dtype}", field="--dtype")


def movable_objects(scene: Scene) -> tuple[str, ...]:
    """Objects the sampler moves (``[ranges.objects]``): what the region metrics call the object."""
    return tuple(o.name for o in scene.default.objects if o.name in scene.ranges.objects)


def _holds_out_meshes(scene: Scene) -> bool:
    return any(r.test_meshes for r in scene.ranges.objects.values())


def plan_splits(scene: Scene, settings: EvalSetSettings) -> tuple[dict[str, dict], dict[str, str]]:
    """The splits this scene can have (each with its stream, sampler split, camera and crop widths), and
    the ones it cannot with the reason."""
    region, path = scene.ranges.camera_region, scene.ranges.camera
    left_out = {}
    if not _holds_out_meshes(scene):
        left_out["unseen_objects"] = "the scene file holds out no meshes (no test_meshes in [ranges.objects])"
    if region is None and path is None:
        left_out["moved_camera"] = "the scene file declares no camera ranges ([ranges.camera])"
    elif region is not None and not region.test_regions:
        left_out["moved_camera"] = "the scene's camera region holds out no boxes (no test_regions in [ranges.camera])"
    elif path is not None and not path.test_stretches:
        left_out["moved_camera"] = "the scene's camera path holds out no stretches (no test_stretches)"
    scene_camera = "scene file" if region is not None else ("path, training stretches" if path is not None
                                                            else "scene file")
    splits = {}
    for name in EVAL_SPLITS:
        if name in left_out:
            continue
        stream = 1 if name == "moved_camera" and "unseen_objects" in left_out else STREAM[name]
        camera = scene_camera
        if name == "unseen_objects" and path is not None and region is None:
            camera = "path, unseen stretches"
        if name == "moved_camera":
            camera = "held-out regions" if region is not None else "path, unseen stretches"
        widths = list(settings.windows) if name == "window_shapes" else [settings.width]
        splits[name] = {"stream": stream, "sampler_split": SAMPLER_SPLIT[name], "camera": camera,
                        "shapes": [[w, settings.height] for w in widths]}
    return splits, left_out


def draw_config(scene: Scene, split: str, seed: int) -> FrameConfig:
    """One evaluation configuration of ``split`` (see the module docstring)."""
    fixed = "default" if scene.ranges.camera_region is not None else "sampled"
    if split in ("unseen_configs", "window_shapes"):
        return sample_config(scene, seed, "train", camera=fixed)
    if split == "unseen_objects":
        return sample_config(scene, seed, "test", camera=fixed)
    if split != "moved_camera":
        raise ValueError(f"unknown evaluation split {split!r}")
    moved = sample_config(scene, seed, "test", camera="sampled")
    if not _holds_out_meshes(scene):
        return moved
    # Training meshes and training-like lights; only the camera is the held-out one.
    return dataclasses.replace(sample_config(scene, seed, "train", camera="default"), camera=moved.camera)


def channels(settings: EvalSetSettings, mask: bool = False) -> tuple[tuple[str, int], ...]:
    """The capture's channels, then the second-seed render, the ladder, and the object mask (if any)."""
    return (CHANNELS + ((SECOND_SEED, 3),) + tuple((ladder_channel(n), 3) for n in settings.ladder)
            + (((OBJECT_CHANNEL, 1),) if mask else ()))


def _seeds(settings: EvalSetSettings, stream: int, i: int) -> dict:
    seq = np.random.SeedSequence([EVAL_STREAM, settings.seed, stream, i])
    state = seq.generate_state(3 + len(settings.ladder))
    s = [int(x & 0x7FFFFFFF) for x in state]
    return {"config": s[0], "reference": s[1], "second": s[2], "ladder": s[3:]}


def plan_evalset(scene: Scene, settings: EvalSetSettings) -> list[dict]:
    """Every frame's index, split, seeds, configuration and crop widths: a pure function of scene and settings."""
    splits, _ = plan_splits(scene, settings)
    plan = []
    for k, (split, info) in enumerate(splits.items()):
        for i in range(settings.frames_per_split):
            seeds = _seeds(settings, info["stream"], i)
            config = draw_config(scene, split, seeds["config"])
            plan.append({"index": k * settings.frames_per_split + i, "split": split, "seed": seeds["config"],
                         "sampler_split": info["sampler_split"], "stream": info["stream"],
                         "widths": [w for w, _ in info["shapes"]], "pt_seeds": seeds, "config": config.to_dict()})
    return plan


def render_order(plan: list[dict]) -> list[dict]:
    """Frames interleaved across splits (each split's first frames first), so an interrupted render already
    holds the first frames of every split."""
    pos = {}
    order = []
    for f in plan:
        pos[f["split"]] = pos.get(f["split"], -1) + 1
        order.append((pos[f["split"]], f["index"], f))
    return [f for _, _, f in sorted(order, key=lambda t: (t[0], t[1]))]


def build_manifest(scene: Scene, settings: EvalSetSettings, plan: list[dict], exposure: float,
                   ladder_spp: list[int]) -> dict:
    from diviewer.gl.renderer import RenderSettings

    splits, left_out = plan_splits(scene, settings)
    objects = movable_objects(scene)
    return {
        "format": FORMAT, "format_version": FORMAT_VERSION, "kind": KIND,
        "scene": scene.name, "scene_hash": scene.file_hash,
        "scene_file": str(scene.path) if scene.path else None,
        "scene_toml": scene.path.read_text() if scene.path else None,
        "resolution": [settings.render_width, settings.height],
        "channels": [list(c) for c in channels(settings, mask=bool(objects))],
        "dtype": settings.dtype, "gt": "pt", "spp": settings.spp, "max_depth": settings.max_depth,
        "seed": settings.seed, "frames": len(plan), "split_fractions": [1.0 / len(splits)] * len(splits),
        "render_settings": asdict(RenderSettings().for_scene(scene)),
        "settings": {**asdict(settings), "window_widths": list(settings.windows)},
        "evalset": {
            "splits": splits, "left_out": left_out, "seed_stream": EVAL_STREAM, "second_seed_channel": SECOND_SEED,
            "ladder_spp": ladder_spp, "ladder_channels": [ladder_channel(n) for n in settings.ladder],
            "crop": "every frame rendered at resolution; each split scored on centred crops of its shapes' widths",
            "object_mask": ({"channel": OBJECT_CHANNEL, "objects": list(objects),
                             "how": "GL render of the frame with only these objects; depth equal to the full frame's"}
                            if objects else None),
            "regions_left_out": None if objects else "the scene file moves no object (no [ranges.objects])",
            "tonemap": {"exposure": exposure, "curve": "diviewer.metrics.tonemap (Reinhard at the exposure, "
                        "gamma 2.2)", "fitted_on": "GL direct light of the square crops of seed streams 0 and 1 "
                        "(encoding.fit_exposure)"},
        },
        "versions": versions(),
        "frame_list": plan,
    }


def object_mask(renderer, config: FrameConfig, depth: np.ndarray, names: tuple[str, ...]) -> np.ndarray:
    """(H, W) float 0/1: pixels where one of the named objects is the visible surface.

    The frame is rendered again with only those objects (same camera, same matrices, so the same
    rasterisation): where its depth equals the full frame's, the object is in front.
    """
    only = dataclasses.replace(config, objects=tuple(o for o in config.objects if o.name in names))
    renderer.render(only, direct=False)
    alone = renderer.read("depth").reshape(depth.shape)
    hit = (alone > 0) & (depth > 0) & (np.abs(alone - depth) <= 1e-5 * np.maximum(depth, 1e-6))
    return hit.astype(np.float32)


class EvalTruth:
    """Mitsuba renders of one evaluation frame (reference, direct, second seed, the ladder) and its object mask."""

    def __init__(self, scene: Scene, settings: EvalSetSettings):
        from diviewer.reference import mitsuba as ref

        self.ref, self.scene, self.settings = ref, scene, settings
        self.variant = ref.select_variant()
        self.objects = movable_objects(scene)
        self.renderer = None
        self.estimator: str | None = None
        """How the last frame's renders were made (`diviewer.reference.split_path.ESTIMATORS`); its sidecar keeps it."""

    def attach(self, ctx, renderer) -> None:
        """The GL renderer that just rendered each frame's buffers (for the object mask)."""
        self.renderer = renderer

    def __call__(self, config: FrameConfig, entry: dict) -> dict[str, np.ndarray]:
        s, seeds = self.settings, entry["pt_seeds"]
        out = {}
        if self.objects:
            # Before the path tracer: the GL renderer still holds this frame's depth.
            out[OBJECT_CHANNEL] = object_mask(self.renderer, config, self.renderer.read("depth"), self.objects)
        frame = self.ref.load_frame(self.scene, config, s.render_width, s.height)
        # every render by the truth's estimator (one pass where the frame allows: split_path)
        out["pt"], out["pt_direct"], self.estimator = frame.full_and_direct(s.spp, seeds["reference"], s.max_depth)
        out[SECOND_SEED] = frame.full_light(s.spp, seeds["second"], s.max_depth)
        for n, seed in zip(s.ladder, seeds["ladder"]):
            out[ladder_channel(n)] = frame.full_light(n, seed, s.max_depth)
        return out


def _fit_exposure(ctx, scene: Scene, plan: list[dict], settings: EvalSetSettings) -> float:
    """The tone map's exposure from the GL direct light of the square crops of streams 0 and 1 (no path tracing)."""
    from diviewer.contract.encoding import fit_exposure
    from diviewer.gl.renderer import Renderer
    from diviewer.scene.loader import config_from_dict

    renderer = Renderer(ctx, scene, settings.render_width, settings.height)
    try:
        direct = [crop(renderer.frame(config_from_dict(scene, f["config"]))["direct"], settings.width)
                  for f in plan if f["stream"] in (0, 1)]
    finally:
        renderer.release()
    return float(fit_exposure(direct))


def _stored_shape(settings: EvalSetSettings) -> SimpleNamespace:
    """What the shared frame writer (data.capture.render_frames_gl) reads: the stored (widest) size."""
    return SimpleNamespace(width=settings.render_width, height=settings.height, dtype=settings.dtype,
                           thumbs=settings.thumbs)


def build_evalset(scene_name: str | Path, out: Path, settings: EvalSetSettings = EvalSetSettings(),
                  log=print, shard: tuple[int, int] = (1, 1), jobs: int = 1) -> dict:
    """Render the frames of the evaluation set that are not complete yet (resumable); returns a summary.

    Frames are rendered split-interleaved (``render_order``). When every frame is present, the noise
    floor and Mitsuba's own error at each ladder count are scored per split (diviewer.evaluation.evaluate) and
    written to ``summary.json``. ``shard`` (k, n) renders only the frames whose index is k - 1 modulo n,
    as ``diviewer capture --shard`` does: shards run side by side into one folder (start one first, so
    that the manifest and its fitted exposure are written once), and whichever finds every frame present
    scores the set (``jobs``: processes the scoring runs in).
    """
    from diviewer.data.capture import clean_stale, render_frames_gl, open_or_create
    from diviewer.gl.context import describe, headless_context
    from diviewer.render import check_reference

    settings.check()
    check_reference("pt")  # a missing extra fails before any GL work
    scene = load_scene(scene_name)
    truth = EvalTruth(scene, settings)
    plan = plan_evalset(scene, settings)
    _, left_out = plan_splits(scene, settings)
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
        clean_stale(ds, {f["index"] for f in plan})
        k, n = shard
        todo = [f for f in render_order(ds.frames)
                if f["index"] % n == k - 1 and ds.check_frame(f["index"]) is not None]
        per_frame = settings.spp * 2 + sum(settings.ladder)
        for split, why in left_out.items():
            log(f"split {split} left out: {why}")
        log(f"evalset {scene.name}{'' if n == 1 else f' shard {k}/{n}'}: {len(ds.indices())} of {len(plan)} frames "
            f"done, {len(todo)} to render at "
            f"{settings.render_width}x{settings.height} (cropped to {settings.width} and {list(settings.windows)}; "
            f"{settings.spp} spp twice + direct + ladder {'/'.join(map(str, settings.ladder))}: {per_frame} full "
            f"samples per pixel per frame, {truth.variant})")
        if todo:
            render_frames_gl(ctx, scene, ds, todo, _stored_shape(settings), truth, describe(ctx), log,
                             label="evalset", done=len(ds.indices()) if n == 1 else 0)
    summary = {"planned": len(plan), "present": len(ds.indices()), "seconds": round(time.perf_counter() - t0, 1)}
    if summary["present"] == len(plan):
        result = _scores(out, todo, log, jobs)
        summary["noise_floor"] = {s: r["methods"]["noise_floor"] for s, r in result["splits"].items()}
    log(f"done: {summary['present']}/{summary['planned']} frames in {out}, {summary['seconds']:.0f} s")
    return summary


def _scores(out: Path, rendered: list[dict], log, jobs: int) -> dict:
    """The complete set's scores (noise floor and ladder per split): ``summary.json`` as written before where this run
    rendered nothing and it is newer than the manifest and every frame (a minute of two cores on Sponza's 72
    frames at each resume of a chain), else scored again and written."""
    from diviewer.evaluation.evaluate import evaluate_evalset

    path = out / "summary.json"
    if not rendered and path.is_file():
        newest = max(p.stat().st_mtime for p in [out / "manifest.json", *(out / "frames").iterdir()])
        if path.stat().st_mtime >= newest:
            try:
                result = json.loads(path.read_text())
                log(f"scores of the complete set: {path}, written after its last frame (delete it to score again)")
                return result
            except (OSError, ValueError):
                pass  # unreadable: scored again below
    return evaluate_evalset([], out, log=log, out=path, jobs=jobs)


def configs_apart(frames: list[dict], others: list[dict]) -> bool:
    """True when no configuration of one frame list (an evaluation set's) appears in the other (a capture's)."""
    mine = {json.dumps(f["config"], sort_keys=True) for f in frames}
    return not any(json.dumps(f["config"], sort_keys=True) in mine for f in others)
