"""How far below its mean does a 64-spp truth's median lie? The bias an L1 loss (which converges to the median of a
noisy target) would carry, per split and region of a full evaluation set.

Usage: python tools/experiments/noise_median.py [--evalset DIR] [--spp 64] [--out OUT.json]

For every pixel of a region with a reference above 1e-4 (luminance), the ratio of the ladder's ``pt_spp{spp}``
image to the evaluation set's reference (>= 1024 spp: its mean, to within its own noise), pooled over the
split's frames: the median of those ratios is what a network fitting the median of many such targets would
learn, relative to the mean. Pooling pixels mixes their noise distributions, so it is an estimate of the typical
median bias, not of any one pixel's. Regions as `tools/experiments/unlit_fit.py` (the evaluation set's object
mask and unlit test). Measures only; needs a full evaluation set (the compact one stores no ladder images).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from diviewer.evaluation.frames import EvalFrames, crop_frame
from diviewer.evaluation.scoring import LUMINANCE
from unlit_fit import REGIONS, frame_regions  # this folder


def ratios(ev: EvalFrames, spp: int) -> dict:
    out = {}
    for split, shapes in ev.splits().items():
        got = {r: [] for r in REGIONS}
        for i in ev.present(split, []):
            f = crop_frame(ev.load(i), shapes[0][0])
            ref = np.asarray(f["pt"], np.float64) @ LUMINANCE
            noisy = np.asarray(f[f"pt_spp{spp}"], np.float64) @ LUMINANCE
            for r, m in frame_regions(f, ev.exposure).items():
                m = m & (ref > 1e-4)
                got[r].append(noisy[m] / ref[m])
        out[split] = {}
        for r, parts in got.items():
            v = np.concatenate(parts) if parts else np.zeros(0)
            out[split][r] = {"pixels": int(v.size), "median": float(np.median(v)) if v.size else None,
                             "mean": float(v.mean()) if v.size else None}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--evalset", type=Path, default=Path("runs/cornell/evalset_fly"))
    ap.add_argument("--spp", type=int, default=64, help="the ladder image to test (the captures' spp)")
    ap.add_argument("--out", type=Path)
    a = ap.parse_args()
    ev = EvalFrames(a.evalset)
    if not ev.ladder_images():
        raise SystemExit(f"{a.evalset}: a compact evaluation set stores no ladder images; give a full one")
    result = {"evalset": str(a.evalset), "spp": a.spp, "splits": ratios(ev, a.spp)}
    for split, rows in result["splits"].items():
        print(f"{split}: " + ", ".join(f"{r} median {v['median']:.3f} mean {v['mean']:.3f} ({v['pixels']} px)"
                                       for r, v in rows.items() if v["pixels"]))
    if a.out:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
