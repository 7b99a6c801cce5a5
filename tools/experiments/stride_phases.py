"""Where a model's grid-locked pattern lies: per frame of an evaluation set, the stride pattern in the shade
(`diviewer eval`'s ``stride_shade``, `diviewer.metrics.stride_pattern`) and its phase grid (`stride_phases`: the mean
relative deviation of the irradiance at each position modulo 8), read as the grid's 2-D Fourier components. A
component (ky, kx) of the 8x8 grid has period 8/ky rows and 8/kx columns: (0, 4) is a pattern alternating every
column, (4, 4) a checkerboard, (4, 0) alternating rows; one stride-2 layer's phase imbalance shows at the k = 4
components, a coarser level's at k = 2 and 1 as well. Prints the frames with the strongest pattern, each with its
phase grid (% of the irradiance) and its largest components.

Usage: python tools/experiments/stride_phases.py --model M.onnx [--evalset runs/sponza/evalset] [--split moved_camera]
           [--top 3] [--out J.json]

The model gets the inputs `diviewer eval` gives it (the set's square splits at 128 wide, each window at its own
width). Measures only.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
SEEN = 0.05
"""A pattern this strong (fraction of the irradiance) is counted in the summary; below it the phase grid is mostly
the scene's own texture and noise (a path-traced truth reads 1-2 %)."""
sys.path.insert(0, str(ROOT))


def components(means: np.ndarray, top: int = 4) -> list[dict]:
    """The largest Fourier components of a phase grid (its mean removed): (ky, kx) with ky, kx in 0..P/2 (the
    conjugate halves folded), each as the RMS it contributes (the grid's RMS is the root of their squares' sum)."""
    p = means.shape[0]
    power = np.abs(np.fft.fft2(means)) ** 2 / p ** 4
    folded: dict[tuple[int, int], float] = {}
    for ky in range(p):
        for kx in range(p):
            key = min((ky, kx), ((-ky) % p, (-kx) % p))
            folded[key] = folded.get(key, 0.0) + float(power[ky, kx])
    ranked = sorted(folded.items(), key=lambda kv: -kv[1])[:top]
    return [{"k": list(k), "period_rows": p / k[0] if k[0] else None, "period_cols": p / k[1] if k[1] else None,
             "rms": float(np.sqrt(v))} for k, v in ranked if v > 0]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", type=Path, required=True)
    ap.add_argument("--evalset", type=Path, default=ROOT / "runs" / "sponza" / "evalset")
    ap.add_argument("--split", default=None, help="one split (default: every split)")
    ap.add_argument("--top", type=int, default=3, help="frames to print in full, the strongest pattern first")
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)

    from diviewer.data.scales import light_scales
    from diviewer.evaluation.frames import EvalFrames, crop_frame, split_key
    from diviewer.evaluation.scoring import regions
    from diviewer.evaluation.evaluate import area_direct_of, model_input, run_model, stored_inputs
    from diviewer.metrics import stride_pattern, stride_phases
    from diviewer.runtime import NeuralGI

    ev = EvalFrames(a.evalset)
    net = NeuralGI(a.model)
    area = area_direct_of(ev, {net.direct_samples} - {1})
    problems = ev.problems()
    rows = []
    for split, shapes in ev.splits().items():
        if a.split and split != a.split:
            continue
        idx = ev.present(split, problems)
        scales = dict(zip(idx, light_scales(ev, idx))) if net.light_scaled else {}
        for shape in shapes:
            for i in idx:
                frame = ev.load(i)
                f = crop_frame(frame, shape[0])
                x = model_input(net, f, frame, area, i, shape[0])
                out = run_model(net, x, scales.get(i), **stored_inputs(net, ev.entry(i), x))
                shade = regions(f, ev.exposure)["shade"]
                read = stride_phases(out, f["albedo"], f["depth"], shade)
                if read is None:
                    continue
                rows.append({"split": split_key(split, shape, shapes), "index": int(i),
                             "stride_shade": stride_pattern(out, f["albedo"], f["depth"], shade),
                             "truth": stride_pattern(f["pt"], f["albedo"], f["depth"], shade),
                             "phases": np.round(read[0], 4).tolist(), "components": components(read[0])})
    rows.sort(key=lambda r: -r["stride_shade"])
    for r in rows[:a.top]:
        print(f"{r['split']} frame {r['index']}: stride {100 * r['stride_shade']:.1f} % (its truth "
              f"{100 * (r['truth'] or 0):.1f} %); phase grid, % of the irradiance (rows y mod 8, columns x mod 8):")
        for line in np.asarray(r["phases"]):
            print("   " + " ".join(f"{100 * v:+5.0f}" for v in line))
        print("   largest components: " + "; ".join(
            f"k={tuple(c['k'])} {100 * c['rms']:.1f} %" for c in r["components"]))
    summary = {}
    for r in rows:
        for c in r["components"][:1] if r["stride_shade"] >= SEEN else []:
            key = f"{r['split']}: k={tuple(c['k'])}"
            summary[key] = summary.get(key, 0) + 1
    print(f"the largest component of each frame with a pattern of {100 * SEEN:g} % or more, frames per split: "
          + "; ".join(f"{k} {n}" for k, n in sorted(summary.items())))
    if a.out:  # one frame a line; the phase grid kept where a pattern is seen
        for r in rows:
            if r["stride_shade"] < SEEN:
                del r["phases"]
        head = json.dumps({"model": str(a.model), "evalset": str(a.evalset), "seen": SEEN,
                           "largest_component_counts": summary})
        body = ",\n  ".join(json.dumps(r) for r in rows)
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(f'{head[:-1]}, "frames": [\n  {body}\n]}}\n')
    return 0


if __name__ == "__main__":
    sys.exit(main())
