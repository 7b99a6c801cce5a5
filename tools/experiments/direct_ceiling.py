"""The ceiling of a model that predicts the path tracer's indirect light exactly: GL direct light + (pt - pt_direct)
against pt, on a capture's split; what separates the rasterizer's direct light from the path tracer's.

Usage: python tools/experiments/direct_ceiling.py --data DATA [--split test] [--frames 200] [--out OUT.json]

A model of target "indirect" composes GL direct + its prediction, so even a perfect prediction leaves the
difference between the GL direct light (shadow map, one point per pixel) and the path tracer's (exact shadows,
box-filtered pixels). Both images share the capture's noise in pt - pt_direct, so the score is that difference
alone (plus pt_direct's own noise). Tone-mapped as `diviewer eval` (the scene's evaluation-set exposure).
Reports the per-frame mean, median and the 10th percentile of tone-mapped PSNR for that composite ("oracle
indirect") and for GL direct against pt_direct over the frames where they differ; frames where they agree exactly
(no direct light in view: no error to score) and frames whose truth is black (no light) are counted, not scored.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from diviewer.data.dataset import Dataset
from diviewer.evaluate import scene_exposure
from diviewer.metrics import tonemap


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    m = float(np.mean((a - b) ** 2))
    return float("inf") if m == 0 else float(10 * np.log10(1.0 / m))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, required=True)
    ap.add_argument("--split", default="test")
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--out", type=Path)
    a = ap.parse_args()
    ds = Dataset(a.data)
    idx = ds.indices(a.split)[: a.frames]
    exposure, source = scene_exposure(ds.manifest["scene"], ds.manifest["scene_hash"], [])
    rows = {"oracle_indirect": [], "gl_direct_vs_pt_direct": []}
    black = 0
    for i in idx:
        f = ds.load(i)
        pt, pt_direct, gl = (np.asarray(f[k], np.float32) for k in ("pt", "pt_direct", "direct"))
        if not pt.any():
            black += 1
            continue
        ref = tonemap(pt, exposure)
        rows["oracle_indirect"].append(_psnr(tonemap(np.maximum(gl + pt - pt_direct, 0.0), exposure), ref))
        rows["gl_direct_vs_pt_direct"].append(_psnr(tonemap(gl, exposure), tonemap(pt_direct, exposure)))
    result = {"data": str(a.data), "split": a.split, "frames": len(idx) - black, "black_frames_left_out": black,
              "exposure": exposure, "exposure_from": source}
    for name, v in rows.items():
        exact = sum(1 for x in v if x == float("inf"))
        v = np.asarray([x for x in v if np.isfinite(x)])
        result[name] = {"mean": float(v.mean()), "median": float(np.median(v)), "p10": float(np.percentile(v, 10)),
                        "frames": int(v.size), "frames_exact": exact}
        print(f"{name:24s} tone-mapped PSNR mean {v.mean():.2f}  median {np.median(v):.2f}  10th pct "
              f"{np.percentile(v, 10):.2f}  ({v.size} frames; {exact} exact: no direct light in view)")
    if a.out:
        a.out.write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
