"""How much of a model's error is the level of its indirect light: its scores with the indirect light scaled.

Usage: python tools/experiments/indirect_gain.py --model M.onnx [--evalset runs/evalsets/sponza]
           [--gain 1.0 --gain 1.2 ...] [--out OUT.json]

A model trained with L1 on a noisy truth tends to the median of its targets, darker than their mean in deep shade
(docs/sponza.md, "Where the dark bias comes from"), and `diviewer eval`'s ``bias_indirect`` and per-frame sums say
how much indirect light it gives each frame against the truth's. This asks what that level costs: every frame of
every split and shape is run once (as `diviewer eval` runs it: the model's guard, its light scale and stored
inputs), then scored, tone-mapped as the set's, with its indirect light (output minus the direct-light input)
multiplied by each ``--gain``. Per split and shape: the mean tone-mapped SSIM and PSNR at each gain, and the median
frame's indirect ratio (the model's sum over the truth's, each less the direct-light input, as `diviewer eval`'s
``sum_indirect`` over ``sum_indirect_ref``). A diagnostic on the evaluation set itself: a gain read off it is not a fix (it would be
fitted on the frames it scores). Measures only.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np


def score_gains(net, ev, area: dict, gains: list[float]) -> dict:
    """Per split key: mean tone-mapped SSIM and PSNR at each gain and the median indirect ratio."""
    from diviewer.data.scales import light_scales
    from diviewer.evaluation.frames import crop_frame, split_key
    from diviewer.evaluation.evaluate import model_input, run_model, stored_inputs
    from diviewer.metrics import psnr, ssim, tonemap

    shapes = ev.splits()
    out = {}
    for split, split_shapes in shapes.items():
        idx = [f["index"] for f in ev.frames if f["split"] == split]
        scales = dict(zip(idx, light_scales(ev, idx))) if net.light_scaled else {}
        for shape in split_shapes:
            scores, ratios = {g: [] for g in gains}, []
            for i in idx:
                frame = ev.load(i)
                f = crop_frame(frame, shape[0])
                x = model_input(net, f, frame, area, i, shape[0])
                y = run_model(net, x, scales.get(i), **stored_inputs(net, ev.entry(i), x))
                truth = tonemap(f["pt"], ev.exposure)
                d = float(x["direct"].sum(dtype=np.float64))
                ref = float(f["pt"].sum(dtype=np.float64)) - d
                if ref > 0:
                    ratios.append((float(y.sum(dtype=np.float64)) - d) / ref)
                for g in gains:
                    t = tonemap(x["direct"] + g * (y - x["direct"]), ev.exposure)
                    scores[g].append((float(ssim(t, truth)), float(psnr(t, truth))))
            key = split_key(split, shape, split_shapes)
            out[key] = {"frames": len(idx), "indirect_ratio_median": float(np.median(ratios)) if ratios else None,
                        "gains": {str(g): {"ssim_tm": float(np.mean([s for s, _ in v])),
                                           "psnr_tm": float(np.mean([p for _, p in v]))} for g, v in scores.items()}}
            print(f"{key}: indirect x{out[key]['indirect_ratio_median']:.2f} (median frame); "
                  + ", ".join(f"gain {g}: {v['ssim_tm']:.3f} / {v['psnr_tm']:.2f} dB"
                              for g, v in out[key]["gains"].items()), flush=True)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", type=Path, required=True)
    ap.add_argument("--evalset", type=Path, default=Path("runs/evalsets/sponza"))
    ap.add_argument("--gain", type=float, action="append", help="a factor on the indirect light (repeat; default "
                                                                  "1, 1.1, 1.2, 1.3, 1.5)")
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    from diviewer.evaluation.frames import EvalFrames
    from diviewer.evaluation.evaluate import area_direct_of
    from diviewer.runtime import NeuralGI

    ev = EvalFrames(a.evalset)
    net = NeuralGI(a.model)
    area = area_direct_of(ev, {net.direct_samples} - {1})
    gains = a.gain or [1.0, 1.1, 1.2, 1.3, 1.5]
    record = {"evalset": str(a.evalset), "model": str(a.model), "edge_guard": net.edge_guard,
              "exposure": ev.exposure, "splits": score_gains(net, ev, area, gains)}
    if a.out:
        from diviewer.outputs import write_json

        write_json(a.out, record)
    return 0


if __name__ == "__main__":
    sys.exit(main())
