"""Does a model fit its own training frames' indirect light? Its summed indirect light over the truth's, on frames of
a capture's train split: a model darker there than the truth underfits; one that is right there and dark only on
the evaluation set does not generalise.

Usage: python tools/experiments/train_fit.py --data runs/sponza/data --model M.onnx [--model ...]
           [--first 1400] [--frames 60] [--seed 0] [--out OUT.json]

``--frames`` frames drawn (seeded) from the first ``--first`` train frames (the frames an ablation trained on, as
``diviewer train --train-frames``). Per model: the pooled ratio sum(output - GL direct) / sum(pt - pt_direct)
(the trainer's target: the path tracer's indirect light), and the per-frame ratios of the 10 brightest and the
10 dimmest frames by their truth's indirect light, and the median per-frame ratio of the frames by the share of their
truth that is direct light (`SHARES`: deep shade, between, in the sun). Measures only.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np


def ratios(rows: list[tuple[float, float]]) -> dict:
    """``rows``: (the model's indirect sum, the truth's) per frame -> the pooled ratio and, ordered by the truth's
    sum, the per-frame ratios of the 10 brightest and the 10 dimmest frames (None where a truth is not > 0)."""
    pooled = sum(a for a, _ in rows) / sum(b for _, b in rows)
    ranked = [a / b if b > 0 else None for a, b in sorted(rows, key=lambda r: r[1])]
    return {"pooled": float(pooled), "brightest_10": ranked[-10:][::-1], "dimmest_10": ranked[:10]}


SHARES = ((0.0, 0.05), (0.05, 0.6), (0.6, 1.0))
"""Buckets of a frame's direct share (sum(pt_direct) / sum(pt)): no sunlit pixel of note in view, some, mostly."""


def by_direct_share(rows: list[tuple[float, float]], shares: list[float]) -> dict:
    """``rows`` as for `ratios`, ``shares`` each frame's direct share -> per bucket of `SHARES` ("0.05-0.6"): its
    frame count and median per-frame ratio (None without a frame whose truth is > 0)."""
    out = {}
    for lo, hi in SHARES:
        r = [a / b for (a, b), s in zip(rows, shares) if b > 0 and (lo <= s < hi or s == hi == 1.0)]
        out[f"{lo:g}-{hi:g}"] = {"frames": len(r), "median_ratio": float(np.median(r)) if r else None}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, required=True)
    ap.add_argument("--model", type=Path, action="append", required=True)
    ap.add_argument("--first", type=int, default=1400)
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    from diviewer.data.dataset import Dataset
    from diviewer.data.scales import dataset_scene
    from diviewer.runtime import NeuralGI, pack_buffers
    from diviewer.scene.loader import config_from_dict

    ds = Dataset(a.data)
    scene = dataset_scene(ds)
    idx = sorted(ds.indices("train"))[:a.first]
    pick = sorted(int(i) for i in np.random.default_rng(a.seed).choice(idx, min(a.frames, len(idx)), replace=False))
    record = {"data": str(a.data), "first": a.first, "frames": pick, "models": {}}
    for path in a.model:
        net = NeuralGI(path)
        rows, shares = [], []
        for i in pick:
            f, entry = ds.load(i), ds.entry(i)
            h, w = f["depth"].shape
            y = net.run(pack_buffers(f), **net.frame_inputs(config_from_dict(scene, entry["config"]), w, h, scene))
            rows.append((float(y.sum(dtype=np.float64) - f["direct"].sum(dtype=np.float64)),
                         float(f["pt"].sum(dtype=np.float64) - f["pt_direct"].sum(dtype=np.float64))))
            shares.append(float(f["pt_direct"].sum(dtype=np.float64) / max(f["pt"].sum(dtype=np.float64), 1e-30)))
        r = record["models"][str(path)] = ratios(rows)
        r["by_direct_share"] = by_direct_share(rows, shares)
        fmt = lambda v: " ".join("-" if x is None else f"{x:.2f}" for x in v)  # noqa: E731
        print(f"{path}: indirect light {r['pooled']:.3f} of the truth's over {len(pick)} train frames; "
              f"brightest 10: {fmt(r['brightest_10'])}; dimmest 10: {fmt(r['dimmest_10'])}; by direct share: "
              + ", ".join(f"{k} {v['frames']} frames x{fmt([v['median_ratio']])}" for k, v in r["by_direct_share"].items()),
              flush=True)
    if a.out:
        from diviewer.outputs import write_json

        write_json(a.out, record)
    return 0


if __name__ == "__main__":
    sys.exit(main())
