"""Accuracy on an object's pixels and on its pixels that receive no direct light, per model, on a dataset split.

Usage: python tools/experiments/object_regions.py --data DATA --split test --object-albedo 0.8 --model M [--model M ...]
       [--out OUT.json]

The object's pixels are those of albedo --object-albedo (on cornell no other surface has it: the centre
object's 0.8 grey against the walls' 0.73); "shaded" are those of them whose direct light is zero. One tone
map for all models (`fit_exposure` on the direct light of the first 200 train frames), PSNR over the region's pixels of all frames pooled, and the per-frame mean of the region PSNR.
Frames whose region has fewer than 50 pixels are left out of that region. For the evaluation set's
region metrics use `diviewer eval --evalset` (object masks rendered, not inferred from the albedo).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from diviewer.data.dataset import Dataset
from diviewer.encoding import fit_exposure
from diviewer.metrics import tonemap
from diviewer.runtime import NeuralGI, pack_buffers


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    m = float(np.mean((a - b) ** 2))
    return float("inf") if m == 0 else 10 * np.log10(1.0 / m)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, required=True)
    ap.add_argument("--split", default="test")
    ap.add_argument("--object-albedo", type=float, required=True)
    ap.add_argument("--model", type=Path, action="append", required=True)
    ap.add_argument("--out", type=Path)
    a = ap.parse_args()
    ds = Dataset(a.data)
    idx = ds.indices(a.split)
    frames = [ds.load(i) for i in idx]
    exposure = fit_exposure_for(ds)
    models = {m.stem: NeuralGI(m) for m in a.model}
    rows = {name: {"object": [], "shaded": []} for name in [*models, "direct"]}
    pooled = {name: {"object": [[], []], "shaded": [[], []]} for name in rows}
    for f in frames:
        obj = (np.abs(f["albedo"] - a.object_albedo).max(axis=-1) < 0.004) & (f["depth"] > 0)
        shaded = obj & (f["direct"].mean(axis=-1) < 1e-4)
        truth = tonemap(f["pt"], exposure)
        outs = {name: model.run(pack_buffers(f)) for name, model in models.items()}
        outs["direct"] = f["direct"]
        for name, out in outs.items():
            est = tonemap(out, exposure)
            for region, mask in (("object", obj), ("shaded", shaded)):
                if mask.sum() < 50:
                    continue
                rows[name][region].append(_psnr(est[mask], truth[mask]))
                pooled[name][region][0].append(est[mask])
                pooled[name][region][1].append(truth[mask])
    result = {"data": str(a.data), "split": a.split, "frames": len(idx), "exposure": exposure, "models": {}}
    for name in rows:
        result["models"][name] = {
            region: {"frames": len(rows[name][region]),
                     "psnr_tm_mean": float(np.mean(rows[name][region])) if rows[name][region] else None,
                     "psnr_tm_pooled": _psnr(np.concatenate(pooled[name][region][0]), np.concatenate(pooled[name][region][1]))
                     if rows[name][region] else None}
            for region in ("object", "shaded")}
    text = json.dumps(result, indent=1)
    print(text)
    if a.out:
        a.out.write_text(text)


def fit_exposure_for(ds: Dataset, frames: int = 200) -> float:
    """One exposure for every model: `fit_exposure` on the direct light of the first train frames."""
    return float(fit_exposure(np.stack([ds.load(i)["direct"] for i in ds.indices("train")[:frames]])))


if __name__ == "__main__":
    main()
