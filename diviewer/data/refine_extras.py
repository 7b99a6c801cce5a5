"""A refinement's extra samples rendered on another machine: ``diviewer data refine --extras DIR``.

`diviewer data refine` renders each frame's extra samples where the dataset is. Sponza's 3,400 frames are 3.2 GB,
and a lent accelerator takes 64 MiB a call and gives back 128 MiB: the dataset cannot travel to it, but what the
extra samples need does (each frame's seed and configuration, the scene's identity), and the samples come back
(two float16 images a frame, 192 KB at 128x128). So:

1. here, `write_job`: the refinement's job for a range of frames (`diviewer data refine-job`): the refined
   manifest without its frame list, the source dataset's hash, and each present frame's index, seed and
   configuration (LZMA-compressed JSON: the configurations repeat the scene's objects);
2. there, `render_extras` (`diviewer data render-extras`): each frame's extra samples exactly as `refine`
   renders them (the same seed, count, depth and one-pass estimator) into a folder: ``FRAME.npy`` (float16,
   H x W x 6: ``pt`` then ``pt_direct``) and its sidecar ``FRAME.json`` (the job's source hash, counts, seed,
   variant, estimator, seconds, the array's checksum); resumable, sharded, and stopped at a deadline between frames;
3. here, `diviewer data refine SRC --spp N --out OUT --extras DIR`: refine's weighted mean with the extra samples
   read instead of rendered, for the frames DIR holds, each checked against what refine would render
   (`diviewer.data.refine.load_extras`);
   the frames it lacks are left to a plain `refine`, which then finds these done.

The extra samples are rounded to float16 (the dataset's own dtype) before the mean: a relative error of at most
2^-11 on three quarters of the refined value (256 spp from 64), below the float16 rounding every stored frame has
and far below the Monte-Carlo noise of 256 samples. A frame refined from extras records where its samples came from
(``refined.elsewhere``: variant, seconds there) and no ``refined.seconds``: the seconds a build's pace reads are
this machine's own.
"""

from __future__ import annotations

import json
import lzma
import time
from pathlib import Path

import numpy as np

from diviewer import imageio
from diviewer.console import progress_bar
from diviewer.data.dataset import frame_name, write_checked
from diviewer.data.lineage import derivation_source, verified_frames
from diviewer.data.refine import CHANNELS, extras_problem, refine_seed, refined_manifest
from diviewer.errors import DiviewerError

JOB_FORMAT = "diviewer-refine-job"
JOB_VERSION = 1


def write_job(src_dir: Path, spp: int, first: int, stop: int, out: Path) -> int:
    """The job of refining ``src_dir`` to ``spp`` for its present frames with ``first <= index < stop``, written
    atomically to ``out``; returns the number of frames in it."""
    src = derivation_source(src_dir, out, "refine")  # verified as `refine` will: a job for a refused source is none
    manifest = refined_manifest(src, spp)
    manifest.pop("frame_list", None)
    frames = [{"index": f["index"], "seed": f["seed"], "config": f["config"]}
              for f in verified_frames(src, "refine", partial=True, log=lambda *_: None) if first <= f["index"] < stop]
    if not frames:
        raise DiviewerError(f"no present frame with {first} <= index < {stop}", path=src.root, field="--frames")
    job = {"format": JOB_FORMAT, "format_version": JOB_VERSION, "source": str(src.root), "source_hash": src.hash,
           "manifest": manifest, "frames": frames}
    with imageio.atomic_path(out) as tmp:
        with lzma.open(tmp, "wt") as f:
            json.dump(job, f)
    return len(frames)


def read_job(path: Path) -> dict:
    """A job file as written by `write_job`; refused, naming the file and the field, where it is not one."""
    try:
        with lzma.open(path, "rt") as f:
            job = json.load(f)
    except (OSError, lzma.LZMAError, ValueError) as exc:
        raise DiviewerError(f"not a refinement job: {exc}", path=path) from None
    if not isinstance(job, dict) or job.get("format") != JOB_FORMAT:
        raise DiviewerError(f"not a refinement job (format is not '{JOB_FORMAT}')", path=path, field="format")
    if job.get("format_version") != JOB_VERSION:
        raise DiviewerError(f"job format version {job.get('format_version')} (this diviewer reads {JOB_VERSION})",
                            path=path, field="format_version")
    return job


def render_extras(job_path: Path, out: Path, shard: tuple[int, int] = (1, 1), deadline: float | None = None,
                  log=print) -> dict:
    """Render the extra samples of this shard's frames of a job into ``out`` (skipping those there and sound), no
    frame begun after the wall-clock time ``deadline``; returns {"rendered", "present", "frames", "seconds"}."""
    from diviewer.data.capture import FLOAT16_MAX
    from diviewer.reference import mitsuba as ref
    from diviewer.scene.loader import config_from_dict, load_recorded_scene

    job = read_job(job_path)
    m = job["manifest"]
    scene = load_recorded_scene(m, job_path, "render the extra samples with the scene the capture was made from")
    old = int(m["refined"]["from_spp"])
    extra, eff_extra = int(m["spp"]) - old, ref.effective_spp(int(m["spp"]) - old)
    width, height = m["resolution"]
    variant = ref.select_variant()
    k, n = shard
    mine = [f for f in job["frames"] if f["index"] % n == k - 1]
    todo = [f for f in mine if extras_problem(out, f["index"]) is not None]
    log(f"extras of {job_path} ({old} -> {m['spp']} spp, {eff_extra} more a frame, {variant}) into {out}: "
        f"{len(mine) - len(todo)} of {len(mine)} frames of shard {k}/{n} there, {len(todo)} to render")
    out.mkdir(parents=True, exist_ok=True)
    t_all, rendered = time.perf_counter(), 0
    progress = progress_bar(len(todo), "extras", "frame")
    try:
        for f in todo:
            if deadline is not None and time.time() >= deadline:
                log(f"deadline: {len(todo) - rendered} frames of shard {k}/{n} not begun")
                break
            seed = refine_seed(f["seed"], old)
            t0 = time.perf_counter()
            frame = ref.load_frame(scene, config_from_dict(scene, f["config"]), width, height)
            full, direct, how = frame.full_and_direct(extra, seed, m["max_depth"])
            seconds = time.perf_counter() - t0
            arr = np.concatenate([full, direct], axis=-1)
            if not np.all(np.isfinite(arr)) or np.abs(arr).max() > FLOAT16_MAX:
                raise DiviewerError(f"frame {f['index']}: extra samples non-finite or beyond float16's range; "
                                    "nothing was written for it", path=job_path)
            write_checked(out / f"{frame_name(f['index'])}.npy", arr.astype(np.float16), {
                "index": f["index"], "source_hash": job["source_hash"], "spp": m["spp"], "from_spp": old,
                "extra_spp": eff_extra, "seed": seed, "variant": variant, "pt_estimator": how,
                "seconds": round(seconds, 3), "dtype": "float16", "channels": list(CHANNELS)})
            rendered += 1
            progress.update()
    finally:
        progress.close()
    return {"rendered": rendered, "present": len(mine) - len(todo) + rendered, "frames": len(mine),
            "seconds": round(time.perf_counter() - t_all, 2)}
