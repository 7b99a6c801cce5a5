"""A capture whose direct light covers each pixel's area: ``diviewer data area-direct``.

Renders only the GL direct light of every frame again, at ``samples`` x ``samples`` times the frame's size,
box-filtered back to it (`diviewer.gl.area`), into a new folder; every other channel (the path tracer's truth, the
G-buffer) is copied as stored. Minutes on a CPU where the capture took hours, so a capture made with the
point-sampled direct light becomes one a model of the area's direct light trains on.

- The manifest is the source's with a ``direct_area`` record (samples per axis, the source's hash), part of the
  dataset's identity (as `diviewer.data.refine`'s ``refined``), and ``direct_area_from`` (the source's folder).
- A model trained on it records ``direct_samples`` on its card (`diviewer export`), and eval, bench, render and
  the viewer feed it the same light.
- Resumable: frames already written (and sound) are kept; the source is never changed.
- The source is verified first, as `diviewer data check` does, and an evaluation set refused
  (`diviewer.data.lineage`); the manifest's ``lineage`` adds this step to the source's.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from diviewer.data.dataset import Dataset
from diviewer.errors import DiviewerError


def direct_samples(manifest: dict) -> int:
    """Samples per axis the dataset's direct light was computed over (1: the pixel's centre)."""
    return int((manifest.get("direct_area") or {}).get("samples", 1))


def area_manifest(src: Dataset, samples: int) -> dict:
    """The source's manifest with the ``direct_area`` record and the step in its ``lineage``."""
    from diviewer.data.lineage import with_step
    from diviewer.gl.area import check_samples

    check_samples(samples, "--samples")
    if samples < 2:
        raise DiviewerError("--samples must be at least 2 (1 is the capture's own direct light)", field="--samples")
    m = json.loads(json.dumps(src.manifest))
    if "direct" not in src.slices:
        raise DiviewerError("the dataset has no direct channel", path=src.root / "manifest.json", field="channels")
    if direct_samples(m) != 1:
        raise DiviewerError(f"its direct light already covers {direct_samples(m)}x{direct_samples(m)} samples; "
                            f"derive from the capture it came from ({m.get('direct_area_from')})",
                            path=src.root / "manifest.json", field="direct_area")
    m["direct_area"] = {"samples": samples, "from_hash": src.hash,
                        "how": "GL direct light at samples x the size, each pixel the mean of its block"}
    m["direct_area_from"] = str(src.root)
    return with_step(src, m, "area-direct", {"samples": samples})


def area_direct(src_dir: Path, out: Path, samples: int, log=print, partial: bool = False) -> dict:
    """Write ``src_dir``'s frames (verified first; ``partial``: an incomplete source's present ones) with the area's
    direct light into ``out``; returns a summary."""
    from diviewer.data.lineage import derivation_source, verified_frames
    from diviewer.data.refine import derive_frames, source_scene
    from diviewer.gl.area import AreaDirect
    from diviewer.gl.context import headless_context
    from diviewer.scene.loader import config_from_dict

    src = derivation_source(src_dir, out, "area-direct")
    manifest = area_manifest(src, samples)
    frames = verified_frames(src, "area-direct", partial, log)
    scene = source_scene(src, manifest, "derive")
    s = src.slices["direct"]
    with headless_context() as ctx:
        area = AreaDirect(ctx, scene, src.width, src.height, samples)

        def per_frame(f: dict, arr: np.ndarray) -> tuple[str, dict]:
            arr[..., s] = area(config_from_dict(scene, f["config"])).astype(arr.dtype)
            return "direct_area", {"samples": samples}

        try:
            return derive_frames(src, frames, out, manifest, "area-direct",
                                 f"render ({samples}x{samples} samples per pixel)", per_frame, log=log)
        finally:
            area.release()
