"""Can a better filter spare Sponza's 128-spp refinement? Filters of a 64- and a 128-spp truth's indirect light,
each scored as `filtered_truth_margin.py` scores the recipe's (issue 26's margin over a model's error, frame by
frame on an evaluation set), and the recipe's filter split into its bias and its noise.

The variants, all over the albedo-divided indirect light ``E`` and weighted by the same geometry (normals' cosine^32,
distance from the pixel's tangent plane over its depth at 1/e for 0.01) as `diviewer.data.truth_filter`:
- ``atrous_L``: the recipe's filter (`TruthFilter`) at L levels;
- ``window_R_oO``: one dense (2R+1)^2 window, Gaussian taps (sigma R / 1.5); order 0 is the weighted mean, order 1 a
  weighted local linear fit in screen space (intercept at the pixel: no ramp bias where a surface ends);
- ``guided_L_S``: the a-trous levels with a range term on the one-level filtered ``E`` as a guide (the relative
  luminance difference over S: an edge of the light itself counts little), as joint bilateral filters do: since
  2026-12-04 the recipe's filter with ``range_sigma = S`` (`TruthFilter`), the same figures to float rounding.

The bias/noise split (``--split-frames``, the recipe's filter at 1-3 levels on the first pass): the filter applied
to the set's 1024-spp truth, against it, is its bias (plus most of that truth's own noise, which it smooths away);
the filtered pass against the filtered truth is what noise is left.

Usage: python tools/experiments/truth_filter_variants.py --eval docs/data/sponza256_ladder/eval_full_ladder.json
           --model-key sponza_k16 [--evalset assets/evalsets/sponza] [--renders runs/filtered_truth_renders]
           [--out docs/data/filtered_truth/variants_k16.json]

The passes are those of `filtered_truth_margin.py` (the same cache and seeds: 2 x 64 spp a frame). Measures only.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from filtered_truth_margin import render_passes  # noqa: E402  (this folder is on sys.path)

POWER, PLANE = 32.0, 0.01
"""The geometry's weights, as the recipe's filter (`sponza_filtered128.toml`)."""


def geometry(normal, depth, fov):
    """The pixels with geometry, their view-space normals and positions and 1 / depth."""
    from diviewer.data.truth_filter import view_positions

    n = np.nan_to_num(normal.astype(np.float32))
    hit = (depth > 0.0) & np.any(n != 0.0, axis=-1)
    pos = view_positions(np.where(hit, depth, 0.0), fov)
    return hit, n, pos, np.where(hit, 1.0 / np.maximum(depth, 1e-6), 0.0).astype(np.float32)


def taps(geo, offsets, step=1):
    """For each tap ``(dy, dx)`` (in units of ``step`` pixels): its offset and the neighbour's geometry weight as the
    recipe's filter weighs it, and a function that reads an image at the neighbour (zero padded)."""
    hit, n, pos, inv_z = geo
    h, w = hit.shape
    r = step * max(max(abs(dy), abs(dx)) for dy, dx in offsets)
    pad = lambda a: np.pad(a, [(r, r), (r, r)] + [(0, 0)] * (a.ndim - 2))  # noqa: E731
    pn, pp, ph = pad(n), pad(pos), pad(hit)
    for dy, dx in offsets:
        y, x = r + dy * step, r + dx * step
        nq, pq = pn[y:y + h, x:x + w], pp[y:y + h, x:x + w]
        cos = np.maximum(np.sum(n * nq, axis=-1), 0.0)
        d = np.abs(np.sum(n * (pq - pos), axis=-1)) * inv_z / PLANE
        yield dy, dx, ph[y:y + h, x:x + w] * cos ** POWER * np.exp(-d * d), \
            (lambda img, y=y, x=x: pad(img)[y:y + h, x:x + w])


def window(e, geo, radius, order):
    """One dense window: the Gaussian-weighted mean (order 0) or the intercept of a weighted local linear fit in
    screen space (order 1, a little ridge on the slopes)."""
    hit = geo[0]
    k = 3 if order else 1
    s = np.zeros(hit.shape + (k, k))
    b = np.zeros(hit.shape + (k, 3))
    sigma = radius / 1.5
    offsets = [(dy, dx) for dy in range(-radius, radius + 1) for dx in range(-radius, radius + 1)]
    for dy, dx, wq, at in taps(geo, offsets):
        wq = wq * np.exp(-(dx * dx + dy * dy) / (2.0 * sigma * sigma))
        f = np.array([1.0, dx / radius, dy / radius][:k])
        s += wq[..., None, None] * np.outer(f, f)
        b += wq[..., None, None] * f[:, None] * at(e)[..., None, :]
    if order:
        s[..., 1, 1] += 1e-3 * s[..., 0, 0]
        s[..., 2, 2] += 1e-3 * s[..., 0, 0]
    ok = hit & (s[..., 0, 0] > 0.0)
    coef = np.linalg.solve(np.where(ok[..., None, None], s, np.eye(k)), np.where(ok[..., None, None], b, 0.0))
    return np.where(ok[..., None], coef[..., 0, :], e).astype(np.float32)


VARIANTS = (["atrous_1", "atrous_2"] + [f"window_{r}_o{o}" for r in (2, 3, 4, 6) for o in (0, 1)]
            + [f"guided_{lv}_{s:g}" for lv in (2, 3, 4) for s in (0.15, 0.3, 0.6)])


def filtered(name, pt, direct, f, fov):
    """The truth ``pt`` (its direct part ``direct``) with its indirect light filtered by the variant ``name``."""
    from diviewer.data.scales import floored_albedo
    from diviewer.data.truth_filter import TruthFilter, filter_truth

    kind, *arg = name.split("_")
    if kind in ("atrous", "guided"):
        settings = TruthFilter(int(arg[0]), POWER, PLANE, float(arg[1]) if kind == "guided" else 0.0)
        return filter_truth(pt, direct, f["albedo"], f["normal"], f["depth"], fov, settings)
    a = floored_albedo(np.asarray(f["albedo"], np.float32)).astype(np.float32)
    geo = geometry(f["normal"], f["depth"], fov)
    e = np.where(geo[0][..., None], (pt - direct) / a, 0.0).astype(np.float32)
    out = window(e, geo, int(arg[0]), int(arg[1][1:]))
    return np.where(geo[0][..., None], direct + a * out, pt)


def bias_and_noise(f, fov, pt, direct, exposure, levels=(1, 2, 3)):
    """The recipe's filter at each level count: its bias (the set's truth filtered, against it) and the noise it
    leaves (the filtered pass against the filtered truth), as tone-mapped MSEs."""
    from diviewer.data.truth_filter import TruthFilter, filter_truth
    from diviewer.metrics import mse, tonemap

    out = {}
    for lv in levels:
        g = lambda img: filter_truth(img, direct, f["albedo"], f["normal"], f["depth"], fov,  # noqa: E731
                                     TruthFilter(lv, POWER, PLANE))
        ref = tonemap(g(f["pt"]), exposure)
        out[f"atrous_{lv}"] = {"bias_mse": mse(ref, tonemap(f["pt"], exposure)),
                               "noise_mse": mse(tonemap(g(pt), exposure), ref)}
    return out


def score_split(ev, record, model_key, key, split_shape, idx, passes, split_frames):
    """One split and window shape: per frame, the model's error, the set's own noise, each variant's margin at
    1 and 2 passes; and the bias/noise split on the first ``split_frames`` frames."""
    from diviewer.evaluation.frames import crop, crop_frame
    from diviewer.metrics import mse, psnr_error, tonemap
    from diviewer.evaluation.truthmargin import margin_db, summarize

    model = {r["index"]: psnr_error(r["psnr_tm"]) for r in record["splits"][key]["methods"][model_key]["per_frame"]}
    rows = []
    for n, i in enumerate(idx):
        f = crop_frame(ev.load(i), split_shape)
        fov = ev.entry(i)["config"]["camera"]["fov"]
        truth = tonemap(f["pt"], ev.exposure)
        noise = mse(tonemap(f["pt_b"], ev.exposure), truth) / 2.0
        row = {"index": i, "model_mse": model[i], "truth_noise_mse": noise}
        for c in (1, 2):
            pt = crop(passes[i]["pt"][:c].mean(axis=0), split_shape)
            direct = crop(passes[i]["direct"][:c].mean(axis=0), split_shape)
            for name in VARIANTS:
                e = mse(tonemap(filtered(name, pt, direct, f, fov), ev.exposure), truth)
                row[f"margin_{64 * c}_{name}"] = margin_db(model[i], e, noise)
            if c == 1 and n < split_frames:
                row["bias_noise_64"] = bias_and_noise(f, fov, pt, direct, ev.exposure)
        rows.append(row)
    names = [f"{64 * c}_{v}" for c in (1, 2) for v in VARIANTS]
    return {"per_truth": {nm: summarize(rows, f"margin_{nm}") for nm in names}, "frames": rows}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--eval", type=Path, required=True, help="a `diviewer eval` JSON of the model (per-frame scores)")
    ap.add_argument("--model-key", required=True)
    ap.add_argument("--evalset", type=Path, default=Path("assets/evalsets/sponza"))
    ap.add_argument("--renders", type=Path, default=Path("runs/filtered_truth_renders"))
    ap.add_argument("--split-frames", type=int, default=5, help="frames a split given the bias/noise split")
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    from diviewer.evaluation.frames import EvalFrames, split_key
    from diviewer.scene.loader import load_recorded_scene

    record = json.loads(a.eval.read_text())
    ev = EvalFrames(a.evalset)
    scene = load_recorded_scene(ev.manifest, ev.root / "manifest.json", "render it with the scene it was made with")
    out = {"eval": str(a.eval), "model": a.model_key, "evalset": str(ev.root), "exposure": ev.exposure,
           "pass_spp": 64, "variants": VARIANTS, "splits": {}}
    problems = ev.problems()
    for split, shapes in ev.splits().items():
        idx = ev.present(split, problems)
        passes = {i: render_passes(ev, ev.entry(i), scene, 2, 64, a.renders) for i in idx}
        for shape in shapes:
            key = split_key(split, shape, shapes)
            if a.model_key not in record["splits"].get(key, {}).get("methods", {}):
                continue
            res = out["splits"][key] = score_split(ev, record, a.model_key, key, shape[0], idx, passes,
                                                   a.split_frames)
            best = sorted(((s["median_db"], n) for n, s in res["per_truth"].items() if s["frames"]), reverse=True)
            print(f"{key}: median margin " + "; ".join(f"{n} {m:+.1f}" for m, n in best[:6]), flush=True)
    if a.out:
        from diviewer.outputs import write_json

        write_json(a.out, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
