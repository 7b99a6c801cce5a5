"""Where the error of the evaluation set's "object without direct light" region lies: on the region's boundary
(pixels beside a lit pixel or beside the object's silhouette) or inside it, per model and split.

Usage: python tools/experiments/unlit_edges.py --model M [--model M ...] [--evalset DIR] [--out OUT.json]

The region is `diviewer.evaluation.scoring.regions`' ``object_unlit`` (the object's mask, GL direct light below the
threshold), tone-mapped as `diviewer eval` does. A pixel is *interior* when its eight neighbours are in the
region too, else *edge*: there the path tracer's box-filtered pixel mixes lit and unlit surfaces, or object and
wall, where the G-buffer point-samples one of them. For each model, the evaluation set's second-seed image
(``noise_floor``) and each split: the region's PSNR as `diviewer eval` reports it (the mean over frames of each
frame's PSNR), and the PSNR pooled over all frames' pixels for the whole region, its interior and its edge, with
the pixel counts, and each frame's PSNR, pixel count and radiance bias (``per_frame``). Measures only;
`diviewer eval`'s region metrics are unchanged.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from diviewer.data.scales import light_scales
from diviewer.evaluation.evaluate import area_direct_of, model_input, run_model, stored_inputs
from diviewer.evaluation.frames import EvalFrames, crop_frame, default_evalset
from diviewer.evaluation.scoring import regions
from diviewer.metrics import tonemap
from diviewer.runtime import NeuralGI


def interior(mask: np.ndarray) -> np.ndarray:
    """Pixels of ``mask`` whose 8 neighbours are in ``mask`` too (outside the image counts as outside)."""
    p = np.pad(mask, 1)
    out = mask.copy()
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            out &= p[1 + dy:1 + dy + mask.shape[0], 1 + dx:1 + dx + mask.shape[1]]
    return out


def _psnr(se: float, n: int) -> float | None:
    return None if n == 0 else (float("inf") if se == 0 else float(10 * np.log10(n / se)))


def centre_mesh(entry: dict) -> str:
    """The mesh the frame's centre object wears (the one object whose mesh the sampler draws)."""
    objects = entry["config"].get("objects", [])
    return next((o.get("mesh", "?") for o in objects if o.get("name") == "center"), "?")


def score(ev: EvalFrames, images) -> dict:
    """Per split: for each method (name -> function of (index, frame) giving linear radiance) the region's
    per-frame mean PSNR and pooled PSNR on all / interior / edge pixels."""
    out = {}
    for split, shapes in ev.splits().items():
        idx = ev.present(split, [])
        acc = {name: {"frames": [], "meshes": [], "se": dict.fromkeys(("all", "interior", "edge"), 0.0),
                      "n": dict.fromkeys(("all", "interior", "edge"), 0), "sums": {}, "rows": []} for name in images}
        for i in idx:
            f = crop_frame(ev.load(i), shapes[0][0])
            m = (regions(f, ev.exposure) or {}).get("object_unlit")
            if m is None or not m.any():
                continue
            parts = {"all": m, "interior": interior(m), "edge": m & ~interior(m)}
            ref = tonemap(f["pt"], ev.exposure)
            for name, image in images.items():
                out_i = image(i, f)
                d2 = np.sum((tonemap(out_i, ev.exposure) - ref) ** 2, axis=-1) / 3.0
                a = acc[name]
                a["frames"].append(_psnr(float(d2[m].sum()), int(m.sum())))
                a["meshes"].append(centre_mesh(ev.entry(i)))
                made, truth = float(out_i[m].sum()), float(f["pt"][m].sum())
                got = a["sums"].setdefault(a["meshes"][-1], [0.0, 0.0])
                got[0] += made
                got[1] += truth
                a["rows"].append({"index": int(i), "mesh": a["meshes"][-1], "pixels": int(m.sum()),
                                  "psnr": a["frames"][-1], "bias": made / truth - 1.0 if truth > 0 else None})
                for part, pm in parts.items():
                    a["se"][part] += float(d2[pm].sum())
                    a["n"][part] += int(pm.sum())
        out[split] = {name: {"frames": len(a["frames"]),
                             "per_frame_mean": float(np.mean(a["frames"])) if a["frames"] else None,
                             **{f"pooled_{p}": _psnr(a["se"][p], a["n"][p]) for p in a["se"]},
                             **{f"pixels_{p}": a["n"][p] for p in a["n"]},
                             "by_mesh": {mesh: float(np.mean([v for v, k in zip(a["frames"], a["meshes"]) if k == mesh]))
                                         for mesh in sorted(set(a["meshes"]))},
                             "bias_by_mesh": {mesh: float(t[0] / t[1] - 1.0) if t[1] > 0 else None
                                              for mesh, t in sorted(a["sums"].items())},
                             "per_frame": a["rows"]}
                      for name, a in acc.items()}
    return out


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", type=Path, action="append", required=True)
    ap.add_argument("--evalset", type=Path, help="default: the shipped compact set of the first model's scene")
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    nets = {str(p): NeuralGI(p) for p in a.model}
    ev = EvalFrames(a.evalset or default_evalset(next(iter(nets.values())).meta["scene"]))
    every = [f["index"] for f in ev.frames]
    scales = dict(zip(every, light_scales(ev, every)))

    area = area_direct_of(ev, {net.direct_samples for net in nets.values()} - {1})

    def model_image(net):
        def image(i, f):
            if net.direct_samples > 1:  # fed and composed over the area's light, as diviewer eval does
                f = model_input(net, f, ev.load(i), area, i, f["pt"].shape[1])
            return run_model(net, f, scales[i] if net.light_scaled else None, **stored_inputs(net, ev.entry(i), f))
        return image

    images = {**{name: model_image(net) for name, net in nets.items()},
              "noise_floor": lambda i, f: f[ev.info["second_seed_channel"]]}
    result = {"evalset": str(ev.root), "exposure": ev.exposure, "models": [str(p) for p in a.model],
              "splits": score(ev, images)}
    for split, rows in result["splits"].items():
        print(f"{split}:")
        for name, r in rows.items():
            cells = " ".join(f"{k[7:]} {r[k]:.2f} ({r['pixels_' + k[7:]]} px)" if r[k] is not None else f"{k[7:]} -"
                             for k in ("pooled_all", "pooled_interior", "pooled_edge"))
            mean = f"{r['per_frame_mean']:.2f}" if r["per_frame_mean"] is not None else "-"
            print(f"  {name:40s} eval's mean {mean:>6} over {r['frames']} frames | pooled: {cells}")
            print(f"  {'':40s} by mesh: " + ", ".join(f"{k} {v:.2f}" for k, v in r["by_mesh"].items()))
            print(f"  {'':40s} radiance bias by mesh (linear, summed over the region): "
                  + ", ".join(f"{k} {v:+.1%}" for k, v in r["bias_by_mesh"].items() if v is not None))
    if a.out:
        a.out.write_text(json.dumps(result, indent=1))
    return result


if __name__ == "__main__":
    main()
