"""Why a model scores lower on square frames than in wide windows: the frame's content, or the context it is given.

Usage: python tools/experiments/crop_context.py --model M.onnx [--model ...] [--evalset runs/evalsets/sponza]
           [--width 128] [--out OUT.json]

The evaluation set's square splits are 128x128 renders and its windows 228x128 renders (4:3 a centred crop). A
model's SSIM can differ between them for two reasons: what the frames show (a square holds the view's centre, the
windows its sides too), or what the network sees (run on a square, its receptive field meets the frame's edge 50
columns sooner on each side). The window split's 228x128 frames tell them apart. For each frame, tone-mapped as
`diviewer eval` scores it, against the same truth pixels:

- ``full``: the model run on the whole 228x128 frame, scored over it (the eval's 16:9 figure);
- ``centre_of_full``: the same output, scored over its centred ``--width`` columns only (content: the centre);
- ``centre_alone``: the model run on the centred ``--width`` columns alone (as the square splits are), scored there.

``centre_of_full`` against ``full`` is the content's part; ``centre_alone`` against ``centre_of_full`` is the
context's (the same pixels, less around them). Each also records the model's indirect light over the truth's
(``indirect_ratio``: sums over the scored pixels, the truth's being the path tracer's own, pt - pt_direct, where the
set stores it, else the truth minus the model's direct-light input, as tools/experiments/ssim_budget.py), whose
per-split median says whether the context moves the light's level. Measures only.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np


def crop_cols(image: np.ndarray, width: int) -> np.ndarray:
    from diviewer.evalframes import crop

    return crop(image, width)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", type=Path, action="append", required=True)
    ap.add_argument("--evalset", type=Path, default=Path("runs/evalsets/sponza"))
    ap.add_argument("--split", default="window_shapes")
    ap.add_argument("--width", type=int, default=128)
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    from diviewer.data.scales import light_scales
    from diviewer.evalframes import EvalFrames, crop_frame
    from diviewer.evaluate import area_direct_of, model_input, run_model, stored_inputs
    from diviewer.metrics import psnr, ssim, tonemap
    from diviewer.runtime import NeuralGI

    ev = EvalFrames(a.evalset)
    nets = {str(p): NeuralGI(p) for p in a.model}
    area = area_direct_of(ev, {n.direct_samples for n in nets.values()} - {1})
    problems = {p.index: p.problem for p in ev.problems()}
    idx = ev.present(a.split, problems)
    record = {"evalset": str(a.evalset), "split": a.split, "width": a.width, "exposure": ev.exposure, "models": {}}

    def scores(y, f, direct):
        t, r = tonemap(y, ev.exposure), tonemap(f["pt"], ev.exposure)
        ref = float((f["pt"] - (f["pt_direct"] if "pt_direct" in f else direct)).sum(dtype=np.float64))
        ratio = float((y - direct).sum(dtype=np.float64)) / ref if ref > 0 else None
        return {"ssim": float(ssim(t, r)), "psnr_tm": float(psnr(t, r)), "indirect_ratio": ratio}

    for name, net in nets.items():
        scales = dict(zip(idx, light_scales(ev, idx))) if net.light_scaled else {}
        rows = []
        for i in idx:
            frame = ev.load(i)
            w = frame["pt"].shape[1]
            x = model_input(net, frame, frame, area, i, w)
            y = run_model(net, x, scales.get(i), **stored_inputs(net, ev.entry(i), x))
            f = crop_frame(frame, a.width)
            xc = model_input(net, f, frame, area, i, a.width)
            yc = run_model(net, xc, scales.get(i), **stored_inputs(net, ev.entry(i), xc))
            rows.append({"index": i, "full": scores(y, frame, x["direct"]),
                         "centre_of_full": scores(crop_cols(y, a.width), f, xc["direct"]),
                         "centre_alone": scores(yc, f, xc["direct"]),
                         "centre_alone_vs_of_full_max_abs": float(np.abs(yc - crop_cols(y, a.width)).max())})
        mean = {k: {m: float(np.mean([r[k][m] for r in rows])) for m in ("ssim", "psnr_tm")}
                for k in ("full", "centre_of_full", "centre_alone")}
        for k in mean:  # the median frame's indirect light over the truth's (frames with indirect light)
            got = [r[k]["indirect_ratio"] for r in rows if r[k]["indirect_ratio"] is not None]
            mean[k]["indirect_ratio_median"] = float(np.median(got)) if got else None
        record["models"][name] = {"mean": mean, "frames": rows}
        print(name, ", ".join(f"{k} {v['psnr_tm']:.2f} dB / {v['ssim']:.4f} / indirect x{v['indirect_ratio_median']}"
                              for k, v in mean.items()), flush=True)
    if a.out:
        from diviewer.outputs import write_json

        write_json(a.out, record, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
