"""A dataset of fixed-size crops of a wider capture, for trainers that take one frame shape.

Usage: python tools/experiments/crop_dataset.py SRC OUT [--size 128] [--seed 0]
           [--shade-boost N --object-albedo 0.8] [--below INDEX]

Train frames are cropped at a seeded random offset (a crop of a wider render is the view of the same
camera with its image centre shifted); val and test frames at the centre, so their scores compare
with a square render of the same camera. Each frame's crop offset is recorded in the manifest's
frame list. Resumable: frames already written (checked) are kept. --below INDEX keeps only the source
frames of lower index (a fixed snapshot of a capture that is still growing; captures render in index order).

--shade-boost N (the "more frames with the object in shade" ablation of issue 25): each train frame
whose object is mostly in shade (>= half of its visible pixels receive no direct light; the object's
pixels are those of albedo --object-albedo, which no other surface of the scene has) is written N more
times, each at another random crop, as new frame indices after the source's.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from diviewer import imageio
from diviewer.data.dataset import Dataset, write_frame
from diviewer.errors import DiviewerError


def crop_offsets(src: Dataset, size: int, seed: int) -> dict[int, list[int]]:
    """(x, y) of each frame's crop: random for train, centred otherwise; a pure function of the inputs."""
    if size > src.width or size > src.height:
        raise DiviewerError(f"crop {size} is larger than the frames ({src.width}x{src.height})", field="--size")
    rng = np.random.default_rng([seed, 0xC80])
    offsets = {}
    for f in src.frames:
        draw = rng.integers(0, src.width - size + 1), rng.integers(0, src.height - size + 1)
        centre = (src.width - size) // 2, (src.height - size) // 2
        offsets[f["index"]] = [int(v) for v in (draw if f["split"] == "train" else centre)]
    return offsets


def object_in_shade(frame: dict, albedo: float, tol: float = 0.004) -> bool:
    """Whether >= half of the object's visible pixels (>= 50 of them) receive no direct light."""
    obj = (np.abs(frame["albedo"] - albedo).max(axis=-1) < tol) & (frame["depth"] > 0)
    if obj.sum() < 50:
        return False
    return bool((frame["direct"].mean(axis=-1)[obj] < 1e-4).mean() >= 0.5)


def crop_dataset(src_dir: Path, out: Path, size: int = 128, seed: int = 0, shade_boost: int = 0,
                 object_albedo: float | None = None, below: int | None = None, log=print) -> int:
    src = Dataset(src_dir)
    offsets = crop_offsets(src, size, seed)
    manifest = json.loads(json.dumps(src.manifest))
    if below is not None:
        manifest["frame_list"] = [f for f in manifest["frame_list"] if f["index"] < below]
        src.frames = [f for f in src.frames if f["index"] < below]
        manifest["frames"] = len(manifest["frame_list"])
    manifest["resolution"] = [size, size]
    manifest["derived"] = {"from": str(src_dir), "from_hash": src.hash, "crop": size, "seed": seed,
                           "shade_boost": shade_boost, "object_albedo": object_albedo, "below": below,
                           "tool": "tools/experiments/crop_dataset.py"}
    for f in manifest["frame_list"]:
        f["crop_xy"] = offsets[f["index"]]
        f["source_index"] = f["index"]
    if shade_boost:
        if object_albedo is None:
            raise DiviewerError("--shade-boost needs --object-albedo", field="--object-albedo")
        rng = np.random.default_rng([seed, 0x5AD])
        nxt = max(f["index"] for f in src.frames) + 1
        shaded = [f for f in src.frames if f["split"] == "train" and src.check_frame(f["index"], False) is None
                  and object_in_shade(src.load(f["index"]), object_albedo)]
        for f in shaded:
            for _ in range(shade_boost):
                xy = [int(rng.integers(0, src.width - size + 1)), int(rng.integers(0, src.height - size + 1))]
                manifest["frame_list"].append({**json.loads(json.dumps(f)), "index": nxt, "crop_xy": xy,
                                               "source_index": f["index"]})
                nxt += 1
        log(f"{len(shaded)} train frames with the object in shade, each {shade_boost} more times")
        manifest["frames"] = len(manifest["frame_list"])
    path = out / "manifest.json"
    if path.is_file():
        if json.loads(path.read_text()).get("derived") != manifest["derived"]:
            raise DiviewerError("another derived dataset is there; use another OUT", path=path)
    else:
        imageio.write_text(path, json.dumps(manifest, indent=1))
    (out / "frames").mkdir(parents=True, exist_ok=True)
    ds = Dataset(out)
    done = 0
    for f in ds.frames:
        i, j = f["index"], f["source_index"]
        if src.check_frame(j, verify_checksum=False) is not None or ds.check_frame(i, verify_checksum=False) is None:
            continue
        x, y = f["crop_xy"]
        arr = np.load(src.path(j))[src.height - y - size:src.height - y, x:x + size]  # rows top first; y from the bottom
        info = json.loads(src.path(j, ".json").read_text())
        info.pop("sha256", None)
        write_frame(ds, i, np.ascontiguousarray(arr), {**info, "index": i, "crop_xy": [x, y], "source_index": j})
        done += 1
    log(f"{out}: {done} frames written, {len(ds.indices())}/{len(ds.frames)} present")
    return done


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("src", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--shade-boost", type=int, default=0)
    ap.add_argument("--object-albedo", type=float, default=None)
    ap.add_argument("--below", type=int, default=None)
    a = ap.parse_args(argv)
    try:
        crop_dataset(a.src, a.out, a.size, a.seed, a.shade_boost, a.object_albedo, a.below)
    except DiviewerError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
