"""Where a model's SSIM goes: the level of its indirect light, its fine detail, or its shape at larger scales.

Usage: python tools/experiments/ssim_budget.py --model M.onnx [--model ...] [--evalset assets/evalsets/sponza]
           [--radius 4] [--out OUT.json]

For each frame and shape of the evaluation set (as `diviewer eval` scores it: tone-mapped at the set's exposure,
the model given the same inputs), four tone-mapped SSIMs against the truth, each a direct light plus an indirect
light (the image minus the model's direct-light input):

- ``ssim``: the model as scored.
- ``level_fixed``: the model's indirect light scaled so its sum is the truth's (a perfect global level).
- ``level_fixed_smooth``: that, its albedo-divided indirect light box-filtered over (2 ``--radius`` + 1)^2 pixels and
  multiplied back (the textures kept, the model's detail finer than the filter removed).
- ``truth_smooth``: the truth's indirect light filtered alike: what a model right at every scale above the filter's,
  and smooth below it, would score.

The truth's indirect light (its level for ``level_fixed``, what ``truth_smooth`` filters) is the path tracer's own
(pt - pt_direct) where the set stores ``pt_direct``, else the truth minus the model's direct-light input, which holds
the rasterizer's direct-light error too (smoothed, a shadow edge's error spreads; the record's ``truth_indirect``
says which).

Beside them, the tone-mapped PSNR as scored and with the level fixed (``psnr_tm``, ``psnr_tm_level_fixed``). Where
the set stores the path tracer's direct light of the truth's own paths (``pt_direct``: sets rendered since the
one-pass truth of 2026-11-28), ``oracle`` and ``psnr_tm_oracle`` score the model's direct-light input plus the truth's
exact indirect light (pt - pt_direct): the ceiling of any network that predicts the indirect light, which only the
rasterizer's direct light (its shadow map, its sampling of each pixel) keeps below 1. A frame with no sunlight in
view is exact there (PSNR inf): the oracle's mean PSNR is over the others, and ``oracle_exact_frames`` counts them.
If ``level_fixed`` is far above ``ssim``, the level is wrong; if ``level_fixed_smooth`` is, the model's fine detail
(noise, blotches) costs it; what is left between ``level_fixed_smooth`` and ``truth_smooth`` is the indirect light's
shape at scales above the filter's. Measures only.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from direct_ceiling import finite_mean  # noqa: E402  (an exact oracle frame, PSNR inf, is counted apart)


def box_filter(x: np.ndarray, radius: int) -> np.ndarray:
    """(H, W, C) mean over a (2 radius + 1)^2 window, edges padded by replication (same size out)."""
    if radius <= 0:
        return x.astype(np.float64)
    p = np.pad(x.astype(np.float64), ((radius + 1, radius), (radius + 1, radius), (0, 0)), mode="edge")
    c = p.cumsum(axis=0).cumsum(axis=1)
    n = 2 * radius + 1
    s = c[n:, n:] - c[:-n, n:] - c[n:, :-n] + c[:-n, :-n]
    return s / (n * n)


def smooth_indirect(indirect: np.ndarray, albedo: np.ndarray, radius: int, floor: float = 1e-3) -> np.ndarray:
    """Indirect light whose albedo-divided part (the irradiance) is box-filtered and the albedo multiplied back."""
    a = np.maximum(albedo.astype(np.float64), floor)
    return box_filter(indirect / a, radius) * a


def budget(image: np.ndarray, direct: np.ndarray, truth: np.ndarray, albedo: np.ndarray, exposure: float,
           radius: int, truth_indirect: np.ndarray | None = None) -> dict[str, float]:
    """The four SSIMs of one frame (module doc), and the model's indirect light's sum over the truth's; with
    ``truth_indirect`` (pt - pt_direct), the oracle's SSIM and PSNR too, and the truth's level and smoothed indirect
    light taken from it rather than from ``truth - direct`` (which holds the rasterizer's direct-light error too)."""
    from diviewer.metrics import psnr, ssim, tonemap

    ind = image - direct
    ref = truth - direct if truth_indirect is None else truth_indirect
    total, ref_total = float(ind.sum(dtype=np.float64)), float(ref.sum(dtype=np.float64))
    k = ref_total / total if total > 0 else 1.0
    score = lambda x: float(ssim(tonemap(x, exposure), tonemap(truth, exposure)))  # noqa: E731
    db = lambda x: float(psnr(tonemap(x, exposure), tonemap(truth, exposure)))  # noqa: E731
    best = None if truth_indirect is None else np.maximum(direct + truth_indirect, 0.0)
    oracle = {} if best is None else {"oracle": score(best), "psnr_tm_oracle": db(best)}
    return {**oracle, "ssim": score(image), "level_fixed": score(direct + k * ind),
            "psnr_tm": db(image), "psnr_tm_level_fixed": db(direct + k * ind),
            "level_fixed_smooth": score(direct + smooth_indirect(k * ind, albedo, radius)),
            "truth_smooth": score(direct + smooth_indirect(ref, albedo, radius)),
            "indirect_ratio": total / ref_total if ref_total > 0 else None}


KEYS = ("ssim", "level_fixed", "level_fixed_smooth", "truth_smooth", "oracle", "psnr_tm", "psnr_tm_level_fixed",
        "psnr_tm_oracle")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", type=Path, action="append", required=True)
    ap.add_argument("--evalset", type=Path, default=Path("assets/evalsets/sponza"))
    ap.add_argument("--radius", type=int, default=4)
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    from diviewer.data.scales import light_scales
    from diviewer.evaluation.frames import EvalFrames, crop_frame, split_key
    from diviewer.evaluation.evaluate import area_direct_of, model_input, run_model, stored_inputs
    from diviewer.runtime import NeuralGI

    ev = EvalFrames(a.evalset)
    nets = {str(p): NeuralGI(p) for p in a.model}
    area = area_direct_of(ev, {n.direct_samples for n in nets.values()} - {1})
    problems = {p.index: p.problem for p in ev.problems()}
    record = {"evalset": str(a.evalset), "radius": a.radius, "exposure": ev.exposure, "models": {}}
    for name, net in nets.items():
        splits = record["models"][name] = {}
        for split, shapes in ev.splits().items():
            idx = ev.present(split, problems)
            scales = dict(zip(idx, light_scales(ev, idx))) if net.light_scaled else {}
            for shape in shapes:
                rows = []
                for i in idx:
                    frame = ev.load(i)
                    f = crop_frame(frame, shape[0])
                    x = model_input(net, f, frame, area, i, shape[0])
                    y = run_model(net, x, scales.get(i), **stored_inputs(net, ev.entry(i), x))
                    oracle = f["pt"] - f["pt_direct"] if "pt_direct" in f else None
                    rows.append({"index": i, **budget(y, x["direct"], f["pt"], x["albedo"], ev.exposure, a.radius,
                                                      oracle)})
                key = split_key(split, shape, shapes)
                splits[key] = {"mean": {k: finite_mean([r[k] for r in rows]) for k in KEYS if k in rows[0]},
                               "truth_indirect": "pt - pt_direct" if "psnr_tm_oracle" in rows[0]
                               else "pt - the model's direct light", "frames": rows}
                if "psnr_tm_oracle" in rows[0]:  # frames with no sunlight in view: GL and path tracer agree exactly
                    splits[key]["oracle_exact_frames"] = sum(1 for r in rows if r["psnr_tm_oracle"] == float("inf"))
                print(f"{name} {key}: " + ", ".join(f"{k} {'-' if v is None else format(v, '.3f')}"
                                                    for k, v in splits[key]["mean"].items())
                      + (f" ({splits[key]['oracle_exact_frames']} frames exact: no sunlight in view)"
                         if "oracle_exact_frames" in splits[key] else ""), flush=True)
    if a.out:
        from diviewer.outputs import write_json

        write_json(a.out, record)
    return 0


if __name__ == "__main__":
    sys.exit(main())
