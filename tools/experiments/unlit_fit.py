"""Is the unlit object pixels' darkness a failure to fit or to generalise? The radiance bias of a model on its own
capture's frames, per split (train / val / test) and region, against the capture's 64-spp path-traced truth.

Usage: python tools/experiments/unlit_fit.py --data CAPTURE --model M [--model M ...] [--frames N] [--out OUT.json]

The evaluation set's region metrics (`diviewer.evaluation.scoring.regions`) need an object mask, which captures do not
store: it is rendered again here with GL for each frame (`diviewer.evaluation.evalset.object_mask`, the evaluation set's own
function). The bias of a region is sum(model) / sum(truth) - 1 over its pixels in all scored frames: the truth's
Monte-Carlo noise averages out of a sum, so a 64-spp truth gives the bias without a denoised reference (its PSNR
would not: it is capped by the truth's noise, and is not reported). ``--frames`` frames per split, evenly spaced
over the split. Each model must have been trained on this capture's direct light (its ``direct_samples``).
Measures only.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from diviewer.data.dataset import Dataset
from diviewer.data.scales import dataset_scene, light_scales
from diviewer.evaluation.frames import EvalFrames, default_evalset
from diviewer.evaluation.scoring import LUMINANCE, UNLIT, regions
from diviewer.evaluation.evalset import movable_objects, object_mask
from diviewer.evaluation.evaluate import run_model, stored_inputs
from diviewer.gl.context import headless_context
from diviewer.gl.renderer import Renderer
from diviewer.runtime import NeuralGI
from diviewer.scene import config_from_dict
from unlit_edges import centre_mesh  # this folder

REGIONS = ("object_unlit", "object_lit", "rest_unlit", "rest_lit")


def frame_regions(frame: dict, exposure: float) -> dict[str, np.ndarray]:
    """The evaluation set's two object regions, and the rest of the frame split the same way by its direct light."""
    r = regions(frame, exposure)
    lum = np.asarray(frame["direct"], np.float64) @ LUMINANCE
    unlit = lum * exposure < UNLIT
    obj = r["object"]
    return {"object_unlit": r["object_unlit"], "object_lit": obj & ~unlit, "rest_unlit": ~obj & unlit,
            "rest_lit": ~obj & ~unlit}


def spaced(indices: list[int], n: int) -> list[int]:
    """``n`` of ``indices`` evenly spaced (all of them when there are fewer)."""
    if len(indices) <= n:
        return list(indices)
    return [indices[int(k)] for k in np.linspace(0, len(indices) - 1, n).round()]


def _biases(sums: dict) -> dict:
    """key -> {"bias", "pixels"} from key -> [sum of the model, sum of the truth, pixels]."""
    return {k: {"bias": (s[0] / s[1] - 1.0) if s[1] > 0 else None, "pixels": s[2]} for k, s in sorted(sums.items())}


def measure(ds: Dataset, nets: dict[str, NeuralGI], frames: int, exposure: float) -> dict:
    scene = dataset_scene(ds)
    names = movable_objects(scene)
    out = {}
    with headless_context() as ctx:
        renderer = Renderer(ctx, scene, ds.width, ds.height)
        for split in ("train", "val", "test"):
            idx = spaced(ds.indices(split), frames)
            if not idx:
                continue
            scales = dict(zip(idx, light_scales(ds, idx)))
            sums = {name: {r: [0.0, 0.0, 0] for r in REGIONS} for name in nets}
            by_mesh = {name: {} for name in nets}
            for i in idx:
                f = ds.load(i)
                config = config_from_dict(scene, ds.entry(i)["config"])
                renderer.render(config, direct=False)
                depth = renderer.read("depth").reshape(f["depth"].shape)
                f["object"] = object_mask(renderer, config, depth, names)
                masks = frame_regions(f, exposure)
                for name, net in nets.items():
                    image = run_model(net, f, scales[i] if net.light_scaled else None,
                                      **stored_inputs(net, ds.entry(i), f))
                    for r, m in masks.items():
                        s = sums[name][r]
                        s[0] += float(image[m].sum(dtype=np.float64))
                        s[1] += float(f["pt"][m].sum(dtype=np.float64))
                        s[2] += int(m.sum())
                    s = by_mesh[name].setdefault(centre_mesh(ds.entry(i)), [0.0, 0.0, 0])
                    m = masks["object_unlit"]
                    s[0] += float(image[m].sum(dtype=np.float64))
                    s[1] += float(f["pt"][m].sum(dtype=np.float64))
                    s[2] += int(m.sum())
            out[split] = {"frames": len(idx), "models": {name: _biases(by) for name, by in sums.items()},
                          "object_unlit_by_mesh": {name: _biases(by) for name, by in by_mesh.items()}}
        renderer.release()
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, required=True, help="the capture the models were trained on")
    ap.add_argument("--model", type=Path, action="append", required=True)
    ap.add_argument("--frames", type=int, default=60, help="frames per split")
    ap.add_argument("--out", type=Path)
    a = ap.parse_args()
    ds = Dataset(a.data)
    samples = int((ds.manifest.get("direct_area") or {}).get("samples", 1))
    nets = {str(p): NeuralGI(p) for p in a.model}
    for name, net in nets.items():
        if net.direct_samples != samples:
            raise SystemExit(f"{name}: trained on {net.direct_samples}x{net.direct_samples} direct-light samples, "
                             f"the capture {a.data} holds {samples}x{samples}")
    exposure = EvalFrames(default_evalset(ds.manifest["scene"])).exposure
    result = {"data": str(a.data), "exposure": exposure, "frames_per_split": a.frames,
              "splits": measure(ds, nets, a.frames, exposure)}
    for split, r in result["splits"].items():
        print(f"{split} ({r['frames']} frames):")
        for name, by in r["models"].items():
            print(f"  {name}: " + ", ".join(f"{k} {v['bias']:+.1%} ({v['pixels']} px)" for k, v in by.items()
                                              if v["bias"] is not None))
            print("    object_unlit by mesh: " + ", ".join(f"{k} {v['bias']:+.1%} ({v['pixels']} px)"
                                                          for k, v in r["object_unlit_by_mesh"][name].items()
                                                          if v["bias"] is not None))
    if a.out:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
