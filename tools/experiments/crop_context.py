"""Why a model scores lower on square frames than in wide windows: the frame's content, or the context it is given.

Usage: python tools/experiments/crop_context.py --model M.onnx [--model ...] [--evalset runs/evalsets/sponza]
           [--width 128 [--width 120 ...]] [--guard N] [--out OUT.json]

The evaluation set's square splits are 128x128 renders and its windows 228x128 renders (4:3 a centred crop). A
model's SSIM can differ between them for two reasons: what the frames show (a square holds the view's centre, the
windows its sides too), or what the network sees (run on a square, its receptive field meets the frame's edge 50
columns sooner on each side). The window split's 228x128 frames tell them apart. For each frame and each centred
``--width``, tone-mapped as `diviewer eval` scores it, against the same truth pixels:

- ``full``: the model run on the whole 228x128 frame, scored over it (the eval's 16:9 figure);
- ``centre_of_full``: the same output, scored over its centred columns only (content: the centre);
- ``centre_alone``: the model run on the centred columns alone (as the square splits are), scored there.

``centre_of_full`` against ``full`` is the content's part; ``centre_alone`` against ``centre_of_full`` is the
context's (the same pixels, less around them). Each also records the model's indirect light over the truth's
(``indirect_ratio``: sums over the scored pixels, the truth's being the path tracer's own, pt - pt_direct, where the
set stores it, else the truth minus the model's direct-light input, as tools/experiments/ssim_budget.py), whose
per-split median says whether the context moves the light's level. Per width, ``pooled``: the PSNR of the frames'
pooled squared error both ways and its ``loss_db``, and per column (``columns_psnr_tm``) where the loss sits.

``--guard N`` runs the models with that column guard (`diviewer.padding`; default: each model's own,
`diviewer.runtime.model_edge_guard`); docs/sponza.md's figures of "The frame's edge" were taken before the guard
existed: ``--guard 0`` reproduces them. Measures only.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np


def _scores(y: np.ndarray, f: dict, direct: np.ndarray, exposure: float) -> dict:
    from diviewer.metrics import psnr, ssim, tonemap

    t, r = tonemap(y, exposure), tonemap(f["pt"], exposure)
    ref = float((f["pt"] - (f["pt_direct"] if "pt_direct" in f else direct)).sum(dtype=np.float64))
    ratio = float((y - direct).sum(dtype=np.float64)) / ref if ref > 0 else None
    return {"ssim": float(ssim(t, r)), "psnr_tm": float(psnr(t, r)), "indirect_ratio": ratio}


def _db(mse: np.ndarray) -> np.ndarray:
    return -10.0 * np.log10(np.maximum(mse, 1e-20))


def _summary(rows: list[dict], sq_alone: np.ndarray, sq_of_full: np.ndarray, frames: int) -> dict:
    """A width's per-frame means, median indirect ratio, pooled PSNR both ways and per-column PSNR."""
    mean = {k: {m: float(np.mean([r[k][m] for r in rows])) for m in ("ssim", "psnr_tm")}
            for k in ("full", "centre_of_full", "centre_alone")}
    for k in mean:  # the median frame's indirect light over the truth's (frames with indirect light)
        got = [r[k]["indirect_ratio"] for r in rows if r[k]["indirect_ratio"] is not None]
        mean[k]["indirect_ratio_median"] = float(np.median(got)) if got else None
    alone, of_full = _db(sq_alone.mean() / frames), _db(sq_of_full.mean() / frames)
    return {"mean": mean, "pooled": {"centre_alone_psnr_tm": float(alone), "centre_of_full_psnr_tm": float(of_full),
                                     "loss_db": float(of_full - alone)},
            "columns_psnr_tm": {"centre_alone": _db(sq_alone / frames).round(2).tolist(),
                                "centre_of_full": _db(sq_of_full / frames).round(2).tolist()},
            "frames": rows}


def measure(net, ev, idx: list[int], area: dict, width: int) -> dict:
    """One model at one centred width over the split's frames (the module doc's three scores)."""
    from diviewer.data.scales import light_scales
    from diviewer.evaluation.frames import crop, crop_frame
    from diviewer.evaluation.evaluate import model_input, run_model, stored_inputs
    from diviewer.metrics import tonemap

    scales = dict(zip(idx, light_scales(ev, idx))) if net.light_scaled else {}
    rows, sq_alone, sq_of_full = [], np.zeros(width), np.zeros(width)
    for i in idx:
        frame = ev.load(i)
        x = model_input(net, frame, frame, area, i, frame["pt"].shape[1])
        y = run_model(net, x, scales.get(i), **stored_inputs(net, ev.entry(i), x))
        f = crop_frame(frame, width)
        xc = model_input(net, f, frame, area, i, width)
        yc = run_model(net, xc, scales.get(i), **stored_inputs(net, ev.entry(i), xc))
        rows.append({"index": i, "full": _scores(y, frame, x["direct"], ev.exposure),
                     "centre_of_full": _scores(crop(y, width), f, xc["direct"], ev.exposure),
                     "centre_alone": _scores(yc, f, xc["direct"], ev.exposure)})
        truth = tonemap(f["pt"], ev.exposure)
        sq_alone += ((tonemap(yc, ev.exposure) - truth) ** 2).mean(axis=(0, 2))
        sq_of_full += ((tonemap(crop(y, width), ev.exposure) - truth) ** 2).mean(axis=(0, 2))
    return _summary(rows, sq_alone, sq_of_full, len(idx))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", type=Path, action="append", required=True)
    ap.add_argument("--evalset", type=Path, default=Path("runs/evalsets/sponza"))
    ap.add_argument("--split", default="window_shapes")
    ap.add_argument("--width", type=int, action="append", help="a centred width (repeat; default 128)")
    ap.add_argument("--guard", type=int, default=None, help="the runtime's column guard (default: the model's)")
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    from diviewer.evaluation.frames import EvalFrames
    from diviewer.evaluation.evaluate import area_direct_of
    from diviewer.runtime import NeuralGI

    ev = EvalFrames(a.evalset)
    nets = {str(p): NeuralGI(p, guard=a.guard) for p in a.model}
    area = area_direct_of(ev, {n.direct_samples for n in nets.values()} - {1})
    idx = ev.present(a.split, {p.index: p.problem for p in ev.problems()})
    widths = a.width or [128]
    record = {"evalset": str(a.evalset), "split": a.split, "exposure": ev.exposure, "models": {}}
    for name, net in nets.items():
        record["models"][name] = {"edge_guard": net.edge_guard, "widths": {}}
        for width in widths:
            got = record["models"][name]["widths"][str(width)] = measure(net, ev, idx, area, width)
            print(f"{name} (guard {net.edge_guard}) width {width}: "
                  + ", ".join(f"{k} {v['psnr_tm']:.2f} dB / {v['ssim']:.4f} / indirect x{v['indirect_ratio_median']}"
                              for k, v in got["mean"].items())
                  + f"; pooled loss {got['pooled']['loss_db']:.2f} dB", flush=True)
    if a.out:
        from diviewer.outputs import write_json

        write_json(a.out, record)
    return 0


if __name__ == "__main__":
    sys.exit(main())
