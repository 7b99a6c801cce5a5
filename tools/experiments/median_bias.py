"""Where each reconstruction loss converges on a noisy truth: the per-pixel median (L1), the encoded mean (L2 on
the encoded values) and the mean (L2 on linear radiance, and the relative L2 of Noise2Noise), against the mean.

Usage: python tools/experiments/median_bias.py [--evalset assets/evalsets/sponza] [--spp 64] [--renders 16]
           [--scale 0.5] [--card CARD.json] [--cache C.npz] [--out OUT.json]

A network trained on path-traced targets learns, for each pixel's inputs, the statistic its loss is minimised by
over the targets' noise: the median for L1 (on any monotonic encoding of the radiance, so also on the encoded,
light-scaled, albedo-divided values the trainer uses), the mean of the encoded values for L2 on them, the mean
for L2 on linear radiance. For each frame of the evaluation set this renders the capture's target ``--renders``
times with independent seeds, exactly as the capture does (``pt`` and ``pt_direct`` at ``--spp`` with one seed;
indirect = pt - pt_direct), at ``--scale`` of the frame's stored size, and reports per frame:

- ``median_ratio``, ``encoded_mean_ratio``: the indirect light's sum over the frame under each optimum, over its
  sum under the mean of the renders (``renders x spp`` samples: the truth, to within its noise). 1 is unbiased.
- ``psnr_tm_median``, ``psnr_tm_encoded_mean``: tone-mapped PSNR (the set's exposure, as `diviewer eval`) of the
  mean direct light plus each optimum's indirect light against the mean full image: the score a perfect network
  would reach under that loss, from the bias alone (no network error).

A median ratio well below 1 means an L1 loss on this truth teaches a network too little indirect light. The
encoded mean uses the exposure of ``--card``'s encoding (a model of the scene) over the frame's light scale, as encoding
2-4 do. Measures only; the renders are kept in ``--cache`` (resumable, one frame at a time).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np


def optima(indirect: np.ndarray, exposure: float, radiance_max: float = 1e5) -> dict[str, np.ndarray]:
    """Per pixel over axis 0 (the renders): the mean, the median, and the mean of the encoded values decoded
    (``diviewer.encoding``'s log curve at ``exposure``)."""
    t = np.clip(np.abs(indirect) * exposure, 0.0, radiance_max)
    enc = np.sign(indirect) * np.log1p(t) / math.log1p(radiance_max)
    m = enc.mean(axis=0)
    return {"mean": indirect.mean(axis=0), "median": np.median(indirect, axis=0),
            "encoded_mean": np.sign(m) * np.expm1(np.abs(m) * math.log1p(radiance_max)) / exposure}


def frame_record(full: np.ndarray, direct: np.ndarray, exposure_tm: float, exposure_enc: float) -> dict:
    """``full``, ``direct``: (R, H, W, 3), the renders of one frame. See the module docstring."""
    from diviewer.evaluation.scoring import LUMINANCE
    from diviewer.metrics import psnr, tonemap

    opt = optima(full - direct, exposure_enc)
    d, ref = direct.mean(axis=0), full.mean(axis=0)
    total = float((opt["mean"] @ LUMINANCE).sum())
    rec = {"indirect_sum": total}
    for name in ("median", "encoded_mean"):
        s = float((opt[name] @ LUMINANCE).sum())
        rec[f"{name}_ratio"] = s / total if total > 0 else None
        rec[f"psnr_tm_{name}"] = float(psnr(tonemap(np.maximum(d + opt[name], 0), exposure_tm), tonemap(ref, exposure_tm)))
    return rec


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--evalset", type=Path, default=Path("assets/evalsets/sponza"))
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--renders", type=int, default=16)
    ap.add_argument("--scale", type=float, default=0.5)
    ap.add_argument("--card", type=Path, default=Path("docs/data/sponza_light_ablation/k8_lit_card.json"),
                    help="a model card of the scene: its encoding's exposure is the one the encoded mean uses")
    ap.add_argument("--cache", type=Path)
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    from diviewer.reference.mitsuba import MitsubaFrame
    from diviewer.scene.lights import light_scale
    from diviewer.scene.loader import config_from_dict
    from sun_dependence import evalset_scene  # this folder

    manifest, scene, exposure = evalset_scene(a.evalset)
    a.exposure = float(json.loads(a.card.read_text())["encoding"]["exposure"])
    height = manifest["resolution"][1]
    cache = dict(np.load(a.cache)) if a.cache and a.cache.is_file() else {}
    rows = []
    for f in manifest["frame_list"]:
        config = config_from_dict(scene, f["config"])
        w, h = round(f["stored_width"] * a.scale), round(height * a.scale)
        key = str(f["index"])
        if f"full_{key}" not in cache:
            mf = MitsubaFrame(scene, config, w, h)
            seeds = [1 + 7919 * r for r in range(a.renders)]
            cache[f"full_{key}"] = np.stack([mf.full(a.spp, s) for s in seeds]).astype(np.float32)
            cache[f"direct_{key}"] = np.stack([mf.direct(a.spp, s) for s in seeds]).astype(np.float32)
            if a.cache:
                np.savez(a.cache.with_suffix(".tmp.npz"), **cache)
                a.cache.with_suffix(".tmp.npz").replace(a.cache)
        scale = light_scale(scene, config)
        rec = frame_record(cache[f"full_{key}"], cache[f"direct_{key}"], exposure,
                           a.exposure / scale if scale > 0 else a.exposure)
        rec.update(index=f["index"], split=f["split"], resolution=[w, h])
        rows.append(rec)
        print(f"frame {f['index']} ({f['split']}): median/mean {rec['median_ratio']:.3f}, encoded mean/mean "
              f"{rec['encoded_mean_ratio']:.3f}; tone-mapped PSNR with the median {rec['psnr_tm_median']:.2f} dB, "
              f"the encoded mean {rec['psnr_tm_encoded_mean']:.2f}", flush=True)
    splits = {}
    for s in dict.fromkeys(r["split"] for r in rows):
        mine = [r for r in rows if r["split"] == s]
        splits[s] = {k: float(np.mean([r[k] for r in mine if r[k] is not None]))
                     for k in ("median_ratio", "encoded_mean_ratio", "psnr_tm_median", "psnr_tm_encoded_mean")}
        print(f"{s}: " + ", ".join(f"{k} {v:.3f}" for k, v in splits[s].items()))
    if a.out:
        from diviewer.outputs import write_json

        write_json(a.out, {"evalset": str(a.evalset), "spp": a.spp, "renders": a.renders, "scale": a.scale,
                           "card": str(a.card), "encoding_exposure": a.exposure, "tonemap_exposure": exposure, "splits": splits,
                           "frames": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
