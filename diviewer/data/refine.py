"""Raise a path-traced dataset's sample count without rendering it again: ``diviewer data refine``.

A capture's ground truth at s spp is the mean of s independent samples per pixel. Rendering each frame again
with s' more samples under another seed and taking the weighted mean ``(s pt + s' pt') / (s + s')`` gives
the mean of s + s' independent samples: the same estimate, statistically, as a capture at s + s' spp, for
the cost of the s' samples only. So a dataset captured quickly at a low count (64 spp: trainable today)
becomes, frame by frame and across sessions, one whose truth is clean enough to measure a model against
(Sponza's 64-spp truth is 35-38 dB from a 1024-spp one, its 256-spp 41-43: docs/sponza.md at commit c48f1bc).

- The refined dataset is written into a new folder (the source stays as it was; trainings that used it keep
  resuming). Its manifest is the source's with ``spp`` (and ``settings.spp``) raised, a ``refined``
  record (the source's hash and count, how the new seeds derive) and ``refined_from`` (its folder); the record
  is part of the dataset's identity, so a refined dataset never has the hash of a capture made at that count directly.
- Both ground-truth channels are refined, ``pt`` and ``pt_direct``, with one new seed per frame, so their
  noise stays correlated as a capture's is (indirect = pt - pt_direct). The extra samples come from one pass
  where the frame allows it (`diviewer.reference.split_path`; the frame's sidecar records ``pt_estimator``),
  whatever estimator the source used: both estimate the same images.
- The GL inputs are copied as they are. Resumable like a capture: frames already refined (and sound) are kept,
  ``--shard k/n`` splits the work over processes or machines (`diviewer data merge` joins them).
- Sample counts are the sampler's effective ones (`diviewer.reference.mitsuba.effective_spp`): the weights of
  the mean, and each frame's sidecar, use what was really taken.
- The source is verified first, as `diviewer data check` does (every frame's checksum; an absent frame refused
  unless ``partial``), and refused where it is an evaluation set or its truth was filtered (its lineage:
  `diviewer.data.lineage`); the manifest's ``lineage`` adds this step to the source's.
- A refined dataset refines again (256 spp to 512): its frames weigh by their own effective count (their sidecar's
  ``refined``: 64 + 195 for Sponza's 256), the new seeds derive from the count refined from, and the manifest's
  and each sidecar's ``refined`` keep the record before (``before``). `diviewer build` takes such a dataset, linked in
  as its work folder's ``data``, for the capture at its count (`diviewer.data.capture.refined_stand_in`).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from diviewer.console import progress_bar
from diviewer.data.dataset import Dataset, frame_name, sha256_file, write_frame
from diviewer.data.lineage import derivation_source, verified_frames, with_step
from diviewer.errors import DiviewerError
from diviewer.locks import run_lock, shard_part

CHANNELS = ("pt", "pt_direct")
"""The images a refinement raises, in the order of the six channels of extra samples rendered elsewhere."""
REFINE_STREAM = 0x4EF1
"""Tag of the new seeds' stream: a frame's extra seed is ``SeedSequence([its seed, REFINE_STREAM, source spp])``."""


def refine_seed(frame_seed: int, source_spp: int) -> int:
    """The seed of a frame's extra samples: independent of the capture's own (its seed) and of other refinements."""
    return int(np.random.SeedSequence([int(frame_seed), REFINE_STREAM, int(source_spp)]).generate_state(1)[0] & 0x7FFFFFFF)


def refined_manifest(src: Dataset, spp: int) -> dict:
    """The source's manifest with the new sample count, the ``refined`` record and the step in its ``lineage``
    (`diviewer.data.lineage.with_step`): `refine` and the extras' job (`refine_extras.write_job`) write the same."""
    m = json.loads(json.dumps(src.manifest))
    if m.get("gt") != "pt":
        raise DiviewerError(f"only a path-traced dataset can be refined (its ground truth is '{m.get('gt')}')",
                            path=src.root / "manifest.json", field="gt")
    old = m.get("spp")
    if not isinstance(old, int) or spp <= old:
        raise DiviewerError(f"--spp must be above the dataset's {old} spp, got {spp}", field="--spp")
    missing = [c for c in ("pt", "pt_direct") if c not in src.slices]
    if missing:
        raise DiviewerError(f"the dataset has no {', '.join(missing)} channel to refine",
                            path=src.root / "manifest.json", field="channels")
    # Part of the identity (where the source lies is not: refined_from); a second refinement keeps the first's.
    m["refined"] = {"from_hash": src.hash, "from_spp": old, "seed": f"SeedSequence([frame seed, {REFINE_STREAM:#x}, {old}])",
                    **({"before": m["refined"]} if "refined" in m else {})}
    m["refined_from"] = str(src.root)
    m["spp"] = spp
    if isinstance(m.get("settings"), dict):
        m["settings"]["spp"] = spp
    return with_step(src, m, "refine", {"spp": spp, "from_spp": old})


def source_scene(src: Dataset, manifest: dict, verb: str):
    """The scene of a dataset being derived (refined, its direct light re-rendered), refusing a scene file changed
    since the capture."""
    from diviewer.scene.loader import load_recorded_scene

    return load_recorded_scene(manifest, src.root / "manifest.json",
                               f"it has changed since the capture; {verb} it with the scene it was captured with")


def derive_frames(src: Dataset, frames: list[dict], out: Path, manifest: dict, verb: str, what: str, per_frame,
                  tally: str = "rendered", log=print) -> dict:
    """Write ``frames`` of ``src`` (`diviewer.data.lineage.verified_frames`') into ``out`` (a dataset of ``manifest``),
    each changed in place by ``per_frame(entry, arr) -> (sidecar key, record)``, the record added to its sidecar;
    frames already there (and sound) are kept. Returns `summarize`'s summary with ``tally`` (the frames written now)
    and the seconds. What `diviewer data area-direct` and `filter-truth` share; ``what`` says what each frame gets,
    in the log line."""
    from diviewer.data.capture import open_or_create, summarize

    with run_lock(out, f"data {verb}"):
        ds = open_or_create(out, manifest)
        present = frames
        todo = [f for f in present if ds.check_frame(f["index"]) is not None]
        log(f"{verb} {src.root} -> {out}: {len(present) - len(todo)} of {len(present)} present frames already "
            f"written, {len(todo)} to {what}")
        t_all = time.perf_counter()
        progress = progress_bar(len(present), verb, "frame", initial=len(present) - len(todo))  # resumes there
        try:
            for f in todo:
                i = f["index"]
                arr = np.load(src.path(i))
                key, record = per_frame(f, arr)
                info = json.loads(src.path(i, ".json").read_text())
                info.pop("sha256", None)
                info[key] = record
                write_frame(ds, i, arr, info)
                progress.update()
        finally:
            progress.close()
        summary = summarize(ds)
        summary[tally], summary["seconds"] = len(todo), round(time.perf_counter() - t_all, 2)
        log(f"done: {summary['present']}/{summary['planned']} frames present, {summary['seconds']:.0f} s")
    return summary


def refine(src_dir: Path, out: Path, spp: int, shard: tuple[int, int] = (1, 1), log=print,
           extras: Path | None = None, partial: bool = False) -> dict:
    """Refine the frames of ``src_dir`` (this shard's) to ``spp`` into ``out``; returns a summary. The source is
    verified first (`diviewer.data.lineage`; ``partial``: an incomplete one's present frames). With ``extras`` (a
    folder of extra samples rendered elsewhere: `diviewer.data.refine_extras`), only the frames it holds are refined,
    from its samples, none rendered here."""
    from diviewer.data.capture import FLOAT16_MAX, open_or_create, summarize
    from diviewer.reference import mitsuba as ref
    from diviewer.scene.loader import config_from_dict

    src = derivation_source(src_dir, out, "refine")
    manifest = refined_manifest(src, spp)
    frames = verified_frames(src, "refine", partial, log)
    scene = source_scene(src, manifest, "refine")
    k, n = shard
    old = manifest["refined"]["from_spp"]
    variant = ref.select_variant()
    eff_old, eff_extra = ref.effective_spp(old), ref.effective_spp(spp - old)
    width, height = src.width, src.height
    with run_lock(out, "data refine", shard_part(k, n)):
        ds = open_or_create(out, manifest)
        mine = [f for f in frames if f["index"] % n == k - 1]
        todo = [f for f in mine if ds.check_frame(f["index"]) is not None]
        done = len(mine) - len(todo)  # refined before: the bar starts there
        if extras is not None:
            held = extras_present(extras)
            todo = [f for f in todo if f["index"] in held]
        log(f"refine {src.root} ({old} spp) -> {out} ({spp} spp): {len(mine) - len(todo)} of {len(mine)} present "
            f"frames of shard {k}/{n} already refined, {len(todo)} to " + (
                f"render ({eff_extra} spp each, {variant})" if extras is None else f"take from {extras}"))
        progress = progress_bar(done + len(todo), "refine", "frame", initial=done)
        t_all = time.perf_counter()
        try:
            for f in todo:
                i = f["index"]
                arr = np.load(src.path(i)).astype(np.float32)
                info = json.loads(src.path(i, ".json").read_text())
                info.pop("sha256", None)
                before = info.get("refined")  # a refined source: its frame's own effective count weighs it
                eff_src = int(before["from_spp"]) + int(before["extra_spp"]) if before else eff_old
                seed = refine_seed(f["seed"], old)
                t0 = time.perf_counter()
                if extras is None:
                    frame = ref.load_frame(scene, config_from_dict(scene, f["config"]), width, height)
                    full, direct, how = frame.full_and_direct(spp - old, seed, manifest["max_depth"])
                    extra, record = {"pt": full, "pt_direct": direct}, {"variant": variant}
                else:  # rendered elsewhere: its seconds are that machine's, not this one's (a build's pace)
                    extra, there = load_extras(extras, i, src, spp, seed, eff_extra)
                    how, record = there["pt_estimator"], {"elsewhere": {
                        "variant": there["variant"], "seconds": there["seconds"], "dtype": there["dtype"]}}
                seconds = time.perf_counter() - t0
                for name, new in extra.items():
                    s = src.slices[name]
                    arr[..., s] = (eff_src * arr[..., s] + eff_extra * new) / (eff_src + eff_extra)
                if not np.all(np.isfinite(arr)):
                    raise DiviewerError(f"frame {i}: non-finite values after refining; nothing was written for it",
                                        path=src.path(i))
                if ds.dtype == np.float16 and np.abs(arr).max() > FLOAT16_MAX:
                    raise DiviewerError(f"frame {i}: radiance {np.abs(arr).max():.3g} exceeds float16's range",
                                        path=src.path(i))
                info["refined"] = {"from_spp": eff_src, "extra_spp": eff_extra, "seed": seed, **record,
                                   "pt_estimator": how, **({"seconds": round(seconds, 3)} if extras is None else {}),
                                   **({"before": before} if before else {})}
                write_frame(ds, i, arr.astype(ds.dtype), info)
                progress.set_postfix_str(f"{seconds:.1f}s/frame", refresh=False)
                progress.update()
        finally:
            progress.close()
        summary = summarize(ds)
        summary["rendered"], summary["seconds"] = len(todo), round(time.perf_counter() - t_all, 2)
        log(f"done: {summary['present']}/{summary['planned']} frames present, {summary['seconds']:.0f} s")
    return summary


def extras_problem(out: Path, index: int) -> str | None:
    """Why a frame's extra samples rendered elsewhere (`diviewer.data.refine_extras`) in ``out`` cannot be read
    (absent, no sidecar, checksum), or None."""
    path = out / f"{frame_name(index)}.npy"
    try:
        info = json.loads(path.with_suffix(".json").read_text())
    except (OSError, ValueError):
        return "absent"
    if not path.is_file() or sha256_file(path) != info.get("sha256"):
        return "checksum mismatch (corrupted or edited)"
    return None


def extras_present(folder: Path) -> set[int]:
    """The frame indices a folder of extras has a sidecar for (each one is checked as it is read); a folder that is
    not there is refused (a mistyped path would refine nothing, silently)."""
    if not folder.is_dir():
        raise DiviewerError("no such folder of extra samples", path=folder, field="--extras")
    return {int(p.stem) for p in folder.glob("*.json") if p.stem.isdigit()}


def load_extras(folder: Path, index: int, src: Dataset, spp: int, seed: int, eff_extra: int) -> tuple[dict, dict]:
    """A frame's extra samples from ``folder`` ({"pt", "pt_direct"} as float32) and their record, refused (naming the
    file and the field) unless they are the samples `refine` would render for it: the same source dataset, counts
    and seed, its resolution, intact."""
    path = folder / f"{frame_name(index)}.npy"
    side = path.with_suffix(".json")
    why = extras_problem(folder, index)
    if why is not None:
        raise DiviewerError(f"frame {index}'s extra samples: {why}", path=side if why == "absent" else path)
    info = json.loads(side.read_text())
    want = {"source_hash": src.hash, "spp": spp, "from_spp": int(src.manifest["spp"]), "extra_spp": eff_extra,
            "seed": seed, "index": index, "channels": list(CHANNELS)}
    for field, value in want.items():
        if info.get(field) != value:
            raise DiviewerError(f"frame {index}'s extra samples are not this refinement's: {field} is "
                                f"{info.get(field)!r}, the refinement's {value!r}", path=side, field=field)
    arr = np.load(path)
    if arr.shape != (src.height, src.width, 6):
        raise DiviewerError(f"frame {index}'s extra samples are {arr.shape}, the dataset's frames "
                            f"({src.height}, {src.width}, 6)", path=path, field="shape")
    arr = arr.astype(np.float32)
    return {"pt": arr[..., :3], "pt_direct": arr[..., 3:]}, info
