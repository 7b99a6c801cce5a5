"""The ceiling of a model that predicts the path tracer's indirect light exactly: GL direct light + (pt - pt_direct)
against pt, on a capture's split; what separates the rasterizer's direct light from the path tracer's.

Usage: python tools/experiments/direct_ceiling.py --data DATA [--split test] [--frames 200] [--out OUT.json]
       python tools/experiments/direct_ceiling.py --evalset DIR --cache RENDERS.npz [--spp 1024] [--supersample 2,4]
           [--shadow-size N] [--out OUT.json]

A model of target "indirect" composes GL direct + its prediction, so even a perfect prediction leaves the
difference between the GL direct light (shadow map, one point per pixel) and the path tracer's (exact shadows,
box-filtered pixels). Both images share the capture's noise in pt - pt_direct, so the score is that difference
alone (plus pt_direct's own noise). Tone-mapped as `diviewer eval` (the scene's evaluation-set exposure).
Reports the per-frame mean, median and the 10th percentile of tone-mapped PSNR for that composite ("oracle
indirect") and for GL direct against pt_direct over the frames where they differ; frames where they agree exactly
(no direct light in view: no error to score) and frames whose truth is black (no light) are counted, not scored.

With ``--evalset`` (an evaluation set, which stores no pt_direct): the path tracer's direct light of every frame
is rendered with Mitsuba at ``--spp`` (kept in ``--cache``, resumable), and the same composite is scored per
split and shape against the set's truth, whole frame and the "object without direct light" region (mean over
frames, as `diviewer eval` reports), beside the noise floor (the set's second seed) and the GL direct light alone
(``direct_alone``: as stored, and per factor as rendered now). ``--supersample 2,4`` adds
the same composite with the GL direct light rendered at 2x2 / 4x4 times the size and box-filtered (what a
G-buffer that sees the pixel's area would give); the region stays defined by the stored, point-sampled buffer.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from diviewer.data.dataset import Dataset
from diviewer.evaluation.evaluate import area_direct_of, scene_exposure
from diviewer.metrics import tonemap


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    m = float(np.mean((a - b) ** 2))
    return float("inf") if m == 0 else float(10 * np.log10(1.0 / m))


def finite_mean(values: list[float]) -> float | None:
    """Mean over the frames with an error (an exact frame, PSNR inf, is counted apart); None when there are none
    (tools/experiments/ssim_budget.py takes its oracle's means with it too)."""
    finite = [v for v in values if np.isfinite(v)]
    return float(np.mean(finite)) if finite else None


def evalset_ceiling(root: Path, cache: Path, spp: int, supersample: list[int] | None = None,
                    shadow_size: int | None = None) -> dict:
    """Per split and shape of the evaluation set at ``root``: the oracle composite's scores (see the docstring),
    with the stored GL direct light and, per ``supersample`` factor, with it rendered supersampled (its sun's shadow
    map ``shadow_size`` texels a side; None: the scene file's)."""
    from diviewer.gl.renderer import RenderSettings
    from diviewer.evaluation.frames import EvalFrames, crop_frame, split_key
    from diviewer.evaluation.scoring import regions
    from diviewer.metrics import masked_psnr
    from diviewer.reference.mitsuba import render_direct
    from diviewer.scene import load_scene
    from diviewer.scene.loader import config_from_dict

    ev = EvalFrames(root)
    scene = load_scene(ev.manifest["scene"])  # the shipped scene of that name; its hash must be the set's
    if scene.file_hash != ev.manifest["scene_hash"]:
        raise SystemExit(f"the scene file {ev.manifest['scene']} is not the one the evaluation set was made from")
    w, h = (int(x) for x in ev.manifest["resolution"])
    done = dict(np.load(cache)) if cache.is_file() else {}
    for f in ev.frames:
        key = str(f["index"])
        if key not in done:
            config = config_from_dict(scene, f["config"])
            done[key] = render_direct(scene, config, w, h, spp=spp, seed=7919 + f["index"])
            tmp = cache.with_name(cache.name + ".tmp.npz")
            np.savez(tmp, **done)
            tmp.replace(cache)
            print(f"rendered frame {key} ({len(done)} of {len(ev.frames)})", flush=True)
    settings = RenderSettings(shadow_size=shadow_size).for_scene(scene)
    ss = area_direct_of(ev, set(supersample or []), settings=settings)  # the GL direct light over each pixel's area
    out = {}
    for split, shapes in ev.splits().items():
        for shape in shapes:
            names = ["oracle_indirect", *(f"oracle_indirect_gl_direct_{k}x{k}" for k in ss), "noise_floor",
                     "direct_alone", *(f"direct_alone_{k}x{k}" for k in ss)]
            rows, unlit = {n: [] for n in names}, {n: [] for n in names}
            for i in ev.present(split, []):
                f = crop_frame({**ev.load(i), "pt_direct_mi": done[str(i)],
                                **{f"ss{k}": v[i] for k, v in ss.items()}}, shape[0])
                ref = tonemap(f["pt"], ev.exposure)
                indirect = f["pt"] - f["pt_direct_mi"]
                # the region stays the stored buffer's (point-sampled direct light), whichever direct light is composed
                images = {"oracle_indirect": np.maximum(f["direct"] + indirect, 0.0),
                          **{f"oracle_indirect_gl_direct_{k}x{k}": np.maximum(f[f"ss{k}"] + indirect, 0.0) for k in ss},
                          "noise_floor": f[ev.info["second_seed_channel"]],
                          # the "direct light alone" row as stored, and as the GL direct light rendered now
                          "direct_alone": f["direct"], **{f"direct_alone_{k}x{k}": f[f"ss{k}"] for k in ss}}
                m = (regions(f, ev.exposure) or {}).get("object_unlit")
                for name, img in images.items():
                    t = tonemap(img, ev.exposure)
                    rows[name].append(_psnr(t, ref))
                    if m is not None and m.any():
                        unlit[name].append(masked_psnr(t, ref, m))
            out[split_key(split, shape, shapes)] = {
                name: {"psnr_tm": finite_mean(rows[name]), "frames": len(rows[name]), "psnr_tm_object_unlit":
                       finite_mean(unlit[name]), "frames_object_unlit": len(unlit[name]),
                       "frames_exact": sum(1 for v in rows[name] if v == float("inf")),
                       "frames_object_unlit_exact": sum(1 for v in unlit[name] if v == float("inf"))}
                for name in rows}
    return {"evalset": str(root), "spp_direct": spp, "supersample": list(ss), "shadow_size": settings.shadow_size,
            "exposure": ev.exposure, "splits": out}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path)
    ap.add_argument("--split", default="test")
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--evalset", type=Path)
    ap.add_argument("--cache", type=Path, help="with --evalset: the rendered direct light (npz, resumable)")
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--supersample", default="", help="with --evalset: also compose the GL direct light rendered at "
                    "these factors per axis and box-filtered, e.g. 2,4")
    ap.add_argument("--shadow-size", type=int, default=None, help="with --supersample: the sun's shadow map, texels "
                    "a side (default the scene file's)")
    ap.add_argument("--out", type=Path)
    a = ap.parse_args()
    if a.evalset:
        if not a.cache:
            ap.error("--evalset needs --cache")
        result = evalset_ceiling(a.evalset, a.cache, a.spp, [int(x) for x in a.supersample.split(",") if x.strip()],
                                 a.shadow_size)
        for key, rows in result["splits"].items():
            print(key + ": " + "; ".join(
                f"{n} {r['psnr_tm']:.2f} (unlit object {'-' if r['psnr_tm_object_unlit'] is None else format(r['psnr_tm_object_unlit'], '.2f')}"
                f" over {r['frames_object_unlit'] - r['frames_object_unlit_exact']} frames, "
                f"{r['frames_object_unlit_exact']} exact)" for n, r in rows.items()))
        if a.out:
            a.out.write_text(json.dumps(result, indent=1))
        return
    if not a.data:
        ap.error("give --data or --evalset")
    ds = Dataset(a.data)
    idx = ds.indices(a.split)[: a.frames]
    exposure, source = scene_exposure(ds.manifest["scene"], ds.manifest["scene_hash"], [])
    rows = {"oracle_indirect": [], "gl_direct_vs_pt_direct": []}
    black = 0
    for i in idx:
        f = ds.load(i)
        pt, pt_direct, gl = (np.asarray(f[k], np.float32) for k in ("pt", "pt_direct", "direct"))
        if not pt.any():
            black += 1
            continue
        ref = tonemap(pt, exposure)
        rows["oracle_indirect"].append(_psnr(tonemap(np.maximum(gl + pt - pt_direct, 0.0), exposure), ref))
        rows["gl_direct_vs_pt_direct"].append(_psnr(tonemap(gl, exposure), tonemap(pt_direct, exposure)))
    result = {"data": str(a.data), "split": a.split, "frames": len(idx) - black, "black_frames_left_out": black,
              "exposure": exposure, "exposure_from": source}
    for name, v in rows.items():
        exact = sum(1 for x in v if x == float("inf"))
        v = np.asarray([x for x in v if np.isfinite(x)])
        result[name] = {"mean": float(v.mean()), "median": float(np.median(v)), "p10": float(np.percentile(v, 10)),
                        "frames": int(v.size), "frames_exact": exact}
        print(f"{name:24s} tone-mapped PSNR mean {v.mean():.2f}  median {np.median(v):.2f}  10th pct "
              f"{np.percentile(v, 10):.2f}  ({v.size} frames; {exact} exact: no direct light in view)")
    if a.out:
        a.out.write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
