"""`diviewer capture`: GL inputs + path-traced ground truth for sampled configurations.

Resumable: a killed capture, run again, keeps its finished frames and renders the rest from the same per-frame
seeds, so it ends with the frames an uninterrupted run writes, bit for bit on the same machine and Mitsuba
variant (llvm_ad_rgb gave the same image at 1 and 2 threads); resumed under another variant, the frames
rendered after the resume differ within the path tracer's noise. So do the frames of a capture begun before the
one-pass truth (`diviewer.reference.split_path`) and resumed after: each frame's sidecar records its
``pt_estimator``. Shardable (``--shard k/n`` renders every n-th frame; shards written into one folder, or copied
together, form one dataset). One run per folder (diviewer.locks): a second capture into it refuses, except another
shard with frames of its own.
"""

from __future__ import annotations

import json
import shutil
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from diviewer import imageio
from diviewer.data.dataset import CHANNELS, DERIVED, FORMAT, FORMAT_VERSION, IDENTITY, Dataset, frame_name, write_frame
from diviewer.data.object_lists import share_object_lists
from diviewer.errors import DiviewerError
from diviewer.exposure import still_ev
from diviewer.locks import run_lock, shard_part
from diviewer.console import progress_bar
from diviewer.provenance import versions
from diviewer.scene import FrameConfig, Scene, load_scene, sample_config
from diviewer.scene.sampler import SPLITS, path_parameter

FLOAT16_MAX = 65504.0


@dataclass(frozen=True)
class CaptureSettings:
    """What a capture renders; recorded in the manifest."""

    frames: int = 100
    """Number of frames over all splits."""
    width: int = 128
    height: int = 128
    gt: str = "pt"
    """Ground truth: 'pt' (Mitsuba path tracing) or 'vxgi' (voxel cone tracing, two bounces at full trace
    resolution, stored in the same channels: pt = the VXGI image, pt_direct = the GL direct light)."""
    spp: int = 256
    """Path-tracing samples per pixel."""
    max_depth: int = 16
    """Path length limit of the full render (the direct-only render uses 2)."""
    seed: int = 0
    """Base seed: frame configurations and the path tracer's seeds derive from it."""
    split_fractions: tuple[float, float, float] = (0.8, 0.1, 0.1)
    """Fractions of frames in train, val, test."""
    dtype: str = "float16"
    """Storage type of the frame arrays: float16 (half the disk) or float32 (for radiance over 65504)."""
    thumbs: int = 2
    """PNG thumbnails for the first frames of each split."""
    vxgi_resolution: int = 64
    """VXGI grid resolution (voxels per side) with gt = 'vxgi'."""
    direct_samples: int = 1
    """Samples per axis of the stored GL direct light (`diviewer.gl.area`): 1, each pixel's centre; above, the mean
    over the pixel's area (4: 16 samples), as the path tracer's box filter sees a pixel (docs/generalisation.md at commit c48f1bc)."""


def parse_shard(text: str | None) -> tuple[int, int]:
    """``k/n`` (1-based) to (k, n); None means the whole dataset."""
    if text is None:
        return 1, 1
    try:
        k, n = (int(x) for x in text.split("/"))
    except ValueError:
        k = n = 0
    if not (n >= 1 and 1 <= k <= n):
        raise DiviewerError(f"--shard must be k/n with 1 <= k <= n, got '{text}'", field="--shard")
    return k, n


def split_counts(fractions, frames: int) -> list[int]:
    """Frames per split (train, val, test) of ``frames`` split by ``fractions``: each its floor, the rest to train
    (`plan_frames` plans them; a recipe's check refuses a split left empty)."""
    total = sum(fractions)
    counts = [int(f / total * frames) for f in fractions]
    counts[0] += frames - sum(counts)
    return counts


def plan_frames(scene: Scene, settings: CaptureSettings) -> list[dict]:
    """Every frame's index, split, seed and configuration: a pure function of scene and settings."""
    n = settings.frames
    fr = np.asarray(settings.split_fractions, dtype=np.float64)
    if fr.shape != (3,) or np.any(fr < 0) or fr.sum() <= 0:
        raise DiviewerError(f"split fractions must be 3 non-negative numbers, got {settings.split_fractions}")
    counts = split_counts([float(f) for f in fr], n)
    order = np.random.default_rng([settings.seed, 0x5EED]).permutation(n)
    split_of = np.empty(n, dtype=object)
    start = 0
    for name, c in zip(SPLITS, counts):
        split_of[order[start:start + c]] = name
        start += c
    plan = []
    for i in range(n):
        seed = int(np.random.SeedSequence([settings.seed, i]).generate_state(1)[0] & 0x7FFFFFFF)
        config = sample_config(scene, seed, str(split_of[i]))
        entry = {"index": i, "split": str(split_of[i]), "seed": seed}
        s = path_parameter(scene, seed, str(split_of[i]))
        if s is not None:
            entry["path_s"] = s  # where on the camera path: the split rule is checkable from the manifest
        plan.append({**entry, "config": config.to_dict()})
    return plan


def build_manifest(scene: Scene, settings: CaptureSettings) -> dict:
    from diviewer.gl.renderer import RenderSettings

    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "scene": scene.name,
        "scene_hash": scene.file_hash,
        "scene_file": str(scene.path) if scene.path else None,
        "scene_toml": scene.path.read_text() if scene.path else None,
        "resolution": [settings.width, settings.height],
        "channels": [list(c) for c in CHANNELS],
        "dtype": settings.dtype,
        "gt": settings.gt,
        "spp": settings.spp,
        "max_depth": settings.max_depth,
        "seed": settings.seed,
        "frames": settings.frames,
        "split_fractions": list(settings.split_fractions),
        "render_settings": asdict(RenderSettings().for_scene(scene)),
        # part of the identity only when not the pixel's centre: every capture before it keeps its hash
        **({"direct_area": {"samples": settings.direct_samples, "how": "captured: GL direct light at samples x the "
                            "size, each pixel the mean of its block"}} if settings.direct_samples > 1 else {}),
        **({"vxgi": asdict(vxgi_settings(settings))} if settings.gt == "vxgi" else {}),
        "settings": asdict(settings),
        "versions": versions(),
        "frame_list": plan_frames(scene, settings),
    }


def _same_identity(a: dict, b: dict) -> list[str]:
    return [k for k in (*IDENTITY, *DERIVED) if json.loads(json.dumps(a.get(k))) != json.loads(json.dumps(b.get(k)))]


def open_or_create(out: Path, manifest: dict) -> Dataset:
    """Create the dataset folder, or check that the one there is the same dataset (to resume)."""
    path = out / "manifest.json"
    if path.is_file():
        existing = Dataset(out).manifest  # read and checked: a corrupt manifest is named, not a traceback
        diff = _same_identity(existing, manifest)
        if diff:
            raise DiviewerError(f"a different dataset is already there (differs in: {', '.join(diff)}); "
                                f"use another --out or the same settings to resume", path=out)
    else:
        imageio.write_text(path, json.dumps(share_object_lists(manifest), indent=1))
    (out / "frames").mkdir(parents=True, exist_ok=True)
    return Dataset(out)


class PathTracedGT:
    """Ground truth from Mitsuba: the full image and the direct-only image of a frame."""

    def __init__(self, scene: Scene, settings: CaptureSettings):
        from diviewer.reference import mitsuba as ref

        self.ref, self.scene, self.settings = ref, scene, settings
        self.variant = ref.select_variant()
        self.estimator: str | None = None
        """How the last frame's truth was rendered (`split_path.ESTIMATORS`); its sidecar keeps it."""

    def __call__(self, config: FrameConfig, entry: dict) -> dict[str, np.ndarray]:
        s, seed = self.settings, entry["seed"]
        # Both images from the same paths (one pass, or two with one seed): indirect = full - direct carries none
        # of the direct light's noise.
        frame = self.ref.load_frame(self.scene, config, s.width, s.height)
        full, direct, self.estimator = frame.full_and_direct(s.spp, seed, s.max_depth)
        return {"pt": full, "pt_direct": direct}


def vxgi_settings(settings: CaptureSettings):
    """The VXGI pass's settings for a VXGI-ground-truth capture: full trace resolution, two bounces
    (on cornell, MSE against the path tracer 0.0037 instead of one bounce's 0.0055)."""
    from diviewer.gl.vxgi import VXGISettings

    return VXGISettings(resolution=settings.vxgi_resolution, trace_scale=1, bounces=2)


class VXGIGT:
    """Ground truth from the VXGI pass, in the path tracer's channels: pt = direct + albedo x indirect,
    pt_direct = the GL direct light (so pt - pt_direct is VXGI's indirect light)."""

    variant = "vxgi"

    def __init__(self, settings: CaptureSettings):
        self.settings = vxgi_settings(settings)
        self.settings.validate()
        self.vx = self.renderer = None

    def attach(self, ctx, renderer) -> None:
        """Trace on ``renderer``'s frames (it renders each configuration just before the call)."""
        from diviewer.gl.vxgi import VXGIPass

        self.renderer, self.vx = renderer, VXGIPass(ctx, renderer, self.settings)

    def __call__(self, config: FrameConfig, seed: int) -> dict[str, np.ndarray]:
        self.vx.run(config)
        return {"pt": self.vx.read("vxgi"), "pt_direct": self.renderer.read("direct")}

    def release(self) -> None:
        if self.vx is not None:
            self.vx.release()


def clean_stale(ds: Dataset, mine: set[int]) -> None:
    """Remove temporary files a killed run of this shard left (never another shard's)."""
    for p in (ds.root / "frames").glob(".*"):
        stem = p.name[1:].split(".")[0]
        if stem.isdigit() and int(stem) in mine:
            p.unlink(missing_ok=True)


def capture(scene_name: str | Path, out: Path, settings: CaptureSettings, shard: tuple[int, int] = (1, 1),
            log=print) -> dict:
    """Render the frames of this shard that are not already complete; returns a summary."""
    if settings.gt not in ("pt", "vxgi"):
        raise DiviewerError(f"unknown ground truth '{settings.gt}'; choose pt or vxgi", field="--gt")
    if settings.dtype not in ("float16", "float32"):
        raise DiviewerError(f"--dtype must be float16 or float32, got {settings.dtype}", field="--dtype")
    for name, value, lo in (("--frames", settings.frames, 1), ("--spp", settings.spp, 1),
                            ("--max-depth", settings.max_depth, 2), ("--thumbs", settings.thumbs, 0),
                            ("--seed", settings.seed, 0)):
        if value < lo:
            raise DiviewerError(f"must be at least {lo}, got {value}", field=name)
    from diviewer.gl.area import check_samples

    check_samples(settings.direct_samples, "--direct-samples")
    scene = load_scene(scene_name)
    manifest = build_manifest(scene, settings)
    _check_size(settings)  # before the folder is created: a size the GL context cannot hold leaves nothing
    k, n = shard
    with run_lock(out, "capture", shard_part(k, n)):  # a second run into this folder refuses at once
        ds = open_or_create(out, manifest)
        mine = [f for f in ds.frames if f["index"] % n == k - 1]
        clean_stale(ds, {f["index"] for f in mine})
        todo = [f for f in mine if ds.check_frame(f["index"]) is not None]
        gt_text = f"{settings.spp} spp" if settings.gt == "pt" else f"VXGI {settings.vxgi_resolution}^3"
        log(f"capture {scene.name}: {len(mine) - len(todo)} of {len(mine)} frames of shard {k}/{n} already done, "
            f"{len(todo)} to render at {settings.width}x{settings.height}, {gt_text}")
        t0 = time.perf_counter()
        if todo:
            _render_frames(scene, ds, todo, settings, log, done=len(mine) - len(todo))
        summary = summarize(ds)
        summary["seconds"] = round(time.perf_counter() - t0, 2)
        summary["rendered"] = len(todo)
        log(f"done: {summary['present']}/{summary['planned']} frames present "
            f"({', '.join(f'{s} {c}' for s, c in summary['per_split'].items())}), "
            f"{summary['disk_mb']:.1f} MB, {summary['seconds']:.0f} s")
    return summary


def settings_differ(scene_name: str | Path, out: Path, settings: CaptureSettings) -> list[str]:
    """The identity fields in which the dataset in ``out`` differs from a capture of ``scene_name`` with
    ``settings`` ([] where it is that capture): what `capture` and `refined_stand_in` refuse a folder for. A refined
    dataset's ``refined`` record is no difference: it stands for the capture at its count."""
    expected = build_manifest(load_scene(scene_name), settings)
    return [k for k in _same_identity(Dataset(out).manifest, expected) if k != "refined"]


def refined_stand_in(scene_name: str | Path, out: Path, settings: CaptureSettings, log=print) -> dict | None:
    """A capture refined to ``settings.spp`` in ``out`` (`diviewer data refine`; a build's refined data linked in as
    another build's capture) stands for the capture at that count, to be refined further: checked against these
    settings (all but its ``refined`` record) and complete, nothing rendered; returns `summarize`'s summary, or None
    where ``out`` holds no refined dataset (`capture` renders or resumes it)."""
    if not (out / "manifest.json").is_file():
        return None
    ds = Dataset(out)
    if "refined" not in ds.manifest:
        return None
    diff = settings_differ(scene_name, out, settings)
    if diff:
        raise DiviewerError(f"a refined dataset of other settings is there (differs in: {', '.join(diff)}); use "
                            f"another work folder, or a recipe whose capture it is", path=out / "manifest.json",
                            field=diff[0])
    summary = summarize(ds)
    if summary["present"] != summary["planned"]:
        raise DiviewerError(f"a refined dataset with {summary['planned'] - summary['present']} of its "
                            f"{summary['planned']} frames missing: refine them first (`diviewer data refine "
                            f"{ds.manifest.get('refined_from')} --out {out} --spp {settings.spp}`)",
                            path=out, field="frames")
    log(f"capture {ds.manifest['scene']}: {out} is the capture at {ds.manifest['refined']['from_spp']} spp refined to "
        f"{settings.spp} ({summary['present']} frames): it stands for the capture at {settings.spp}, nothing to render")
    return {**summary, "seconds": 0.0, "rendered": 0}


def _check_size(settings: CaptureSettings) -> None:
    from diviewer.gl.context import check_render_size, headless_context

    with headless_context() as ctx:
        check_render_size(ctx, settings.width, settings.height, "--res")


def _render_frames(scene: Scene, ds: Dataset, todo: list[dict], settings: CaptureSettings, log, done: int = 0) -> None:
    from diviewer.gl.context import describe, headless_context

    gt = PathTracedGT(scene, settings) if settings.gt == "pt" else VXGIGT(settings)
    with headless_context() as ctx:
        render_frames_gl(ctx, scene, ds, todo, settings, gt, describe(ctx), log, done=done)


def render_frames_gl(ctx, scene: Scene, ds: Dataset, todo: list[dict], settings, gt, gl_name: str,
                     log, label: str = "capture", done: int = 0) -> None:
    """Render and write ``todo``: GL buffers plus ``gt(config, frame entry)``, stored in the manifest's channels;
    the progress starts at ``done`` frames rendered before (a resumed capture).

    Shared with the evaluation set (diviewer.evaluation.evalset), whose ground truth adds channels; ``settings``
    needs ``width``, ``height``, ``dtype`` and ``thumbs``.
    """
    from diviewer.gl.display import DisplayPass
    from diviewer.gl.renderer import Renderer, RenderSettings
    from diviewer.scene.loader import config_from_dict

    area = None
    if getattr(settings, "direct_samples", 1) > 1:  # the direct light over each pixel's area (diviewer.gl.area)
        from diviewer.gl.area import AreaDirect

        area = AreaDirect(ctx, scene, settings.width, settings.height, settings.direct_samples)
    # Where the area's light is stored, the frame's own direct light is thrown away: no shadow maps for it (Sponza's
    # 8192 map is ~0.3 s a frame). A ground truth that reads the renderer (VXGI's) keeps them.
    unshadowed = area is not None and not hasattr(gt, "attach")
    renderer = Renderer(ctx, scene, settings.width, settings.height, RenderSettings(shadows=not unshadowed))
    compositor = DisplayPass(ctx, renderer.shaders)
    if hasattr(gt, "attach"):
        gt.attach(ctx, renderer)
    splits = dict.fromkeys(f["split"] for f in ds.frames)  # in order of first appearance
    thumbs = {i for s in splits for i in [f["index"] for f in ds.frames if f["split"] == s][:settings.thumbs]}
    progress = progress_bar(done + len(todo), label, "frame", initial=done)
    try:
        for f in todo:
            config = config_from_dict(scene, f["config"])
            t0 = time.perf_counter()
            buffers = renderer.frame(config)
            if area is not None:
                buffers["direct"] = area(config)
            t1 = time.perf_counter()
            truth = gt(config, f)
            t2 = time.perf_counter()
            planes = {**buffers, **truth}
            arr = np.concatenate([planes[name].reshape(settings.height, settings.width, c) for name, c in ds.channels],
                                 axis=-1)
            bad = [name for name, c in ds.channels if not np.all(np.isfinite(planes[name]))]
            if bad:
                raise DiviewerError(f"frame {f['index']}: non-finite values in {', '.join(bad)} "
                                    f"(configuration in the manifest); nothing was written for it")
            if settings.dtype == "float16" and np.abs(arr).max() > FLOAT16_MAX:
                raise DiviewerError(f"frame {f['index']}: radiance {np.abs(arr).max():.3g} exceeds float16's range; "
                                    f"capture with --dtype float32 (into a new --out)")
            write_frame(ds, f["index"], arr.astype(settings.dtype),
                         {"index": f["index"], "split": f["split"], "variant": gt.variant, "gl_renderer": gl_name,
                          **({"pt_estimator": gt.estimator} if getattr(gt, "estimator", None) else {}),
                          "seconds": {"gl": round(t1 - t0, 4), "gt": round(t2 - t1, 3)}})
            if f["index"] in thumbs:
                ev, _ = still_ev(scene.exposure, scene.auto_exposure, planes["pt"])  # one exposure for the row
                row = [compositor.to_ldr(planes["direct"], ev), compositor.to_ldr(planes["pt"], ev),
                       compositor.to_ldr(planes["pt"] - planes["pt_direct"], ev)]
                imageio.write_png(ds.root / "thumbs" / f"{frame_name(f['index'])}_{f['split']}.png",
                                  np.concatenate(row, axis=1))
            what = "path tracing" if getattr(settings, "gt", "pt") == "pt" else "VXGI truth"  # the evaluation set's truth is traced
            progress.set_postfix_str(f"{what} {t2 - t1:.1f} s a frame ({gt.variant}), GL {t1 - t0:.2f} s",
                                     refresh=False)
            progress.update()
    finally:
        progress.close()
        if hasattr(gt, "release"):
            gt.release()
        if area is not None:
            area.release()
        compositor.release()
        renderer.release()


def summarize(ds: Dataset) -> dict:
    present = ds.indices()
    own = [s for s in dict.fromkeys(f["split"] for f in ds.frames) if s not in SPLITS]
    splits = own or SPLITS  # an evaluation set has splits of its own (unseen_configs, unseen_objects)
    per_split = {s: len(ds.indices(s)) for s in splits}
    disk = sum(p.stat().st_size for p in ds.root.rglob("*") if p.is_file())
    return {"planned": len(ds.frames), "present": len(present), "per_split": per_split, "disk_mb": disk / 2**20}


def merge(sources: list[Path], out: Path, log=print) -> dict:
    """Merge shards captured into separate folders (e.g. on several machines) into one dataset."""
    if not sources:
        raise DiviewerError("nothing to merge")
    manifests = [Dataset(s).manifest for s in sources]
    for s, m in zip(sources[1:], manifests[1:]):
        diff = _same_identity(manifests[0], m)
        if diff:
            raise DiviewerError(f"not shards of the same dataset (differs in: {', '.join(diff)})", path=s)
    ds = open_or_create(out, manifests[0])
    copied = 0
    for src in sources:
        sds = Dataset(src)
        for i in sds.indices():
            if ds.check_frame(i) is None or sds.check_frame(i) is not None:
                continue
            for suffix in (".npy", ".json"):  # the sidecar last: it marks the frame complete
                with imageio.atomic_path(ds.path(i, suffix)) as tmp:
                    shutil.copyfile(sds.path(i, suffix), tmp)
            copied += 1
        for t in (Path(src) / "thumbs").glob("*.png"):
            (out / "thumbs").mkdir(exist_ok=True)
            if not (out / "thumbs" / t.name).exists():
                shutil.copyfile(t, out / "thumbs" / t.name)
    summary = summarize(ds)
    log(f"merged {copied} frames: {summary['present']}/{summary['planned']} present")
    return summary
