"""How far a path-traced truth stands above a model's error once its indirect light is filtered
(`diviewer.data.truth_filter`), frame by frame on an evaluation set, beside the same truth unfiltered: the
"the ground truth's noise floor must be at least 6 dB above the model's error", for a truth `diviewer data
filter-truth` made.

Each frame of the set is path traced again as a capture traces it (`full_and_direct`: the full image and its direct
part from one pass), ``--passes`` times at ``--pass-spp`` under seeds of their own; the first 1, 2, 4, ... passes
averaged are the truth at that many samples, filtered with the frame's G-buffer as stored in the set. Each is scored
against the set's truth as `diviewer eval` scores (tone-mapped, the whole crop of each shape) and its margin over the
model taken as `diviewer.evaluation.truthmargin` takes it: the set's two 1024-spp renders give the reference's own noise, which
comes out of both errors; a filtered truth's error is then its noise and its bias together. The model's errors are
its per-frame scores in a `diviewer eval` JSON of the same set.

Usage: python tools/experiments/filtered_truth_margin.py --eval EVAL.json --model-key sponza_k16
           [--evalset assets/evalsets/sponza] [--pass-spp 64] [--passes 4] [--recipe R.toml] [--filter 1:32:0.01 ...]
           [--renders runs/filtered_truth_renders] [--out OUT.json]

The renders are kept per frame in ``--renders`` (resumable; ~5 s a 64-spp pass of a Sponza frame on a 2-core CPU).
Measures only.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from diviewer.evaluation.truthmargin import MARGIN_DB, margin_db, summarize

SEED_STREAM = 0xF117
"""Tag of the passes' seeds: pass p of a frame is ``SeedSequence([frame seed, SEED_STREAM, p])``."""


def parse_filter(text: str):
    from diviewer.data.truth_filter import TruthFilter
    from diviewer.errors import DiviewerError

    try:
        levels, power, plane, *rest = text.split(":")
        if len(rest) > 1:
            raise ValueError(text)
        return TruthFilter(int(levels), float(power), float(plane), *map(float, rest)).check("--filter")
    except (ValueError, DiviewerError) as exc:
        raise argparse.ArgumentTypeError(f"LEVELS:NORMAL_POWER:PLANE[:RANGE_SIGMA], e.g. 1:32:0.01 or 2:32:0.01:0.6 "
                                         f"(got {text!r})") from exc


def recipe_filters(path: Path | None) -> list:
    """The filter a recipe's truth is filtered with, as a list (empty without ``path``); a recipe that filters
    nothing is refused in one line naming the file and the field."""
    if path is None:
        return []
    from diviewer.errors import DiviewerError
    from diviewer.train.recipe import load_recipe, truth_filter

    try:
        f = truth_filter(load_recipe(path))
    except DiviewerError as exc:
        raise SystemExit(f"{exc}; nothing written") from None
    if f is None:
        raise SystemExit(f"{path}: capture.truth_filter: the recipe filters nothing, there is no filter to score; "
                         "nothing written")
    return [f]


def filter_tag(f) -> str:
    """A filter's name in the output: ``filtered_LEVELS_POWER_PLANE``, ``_rRANGE`` after it with a range term."""
    return f"filtered_{f.levels}_{f.normal_power:g}_{f.plane:g}" + (f"_r{f.range_sigma:g}" if f.range_sigma else "")


def render_passes(ev, entry: dict, scene, passes: int, spp: int, cache: Path) -> dict[str, np.ndarray]:
    """The frame's passes at its rendered resolution: ``pt`` and ``direct``, each (passes, H, W, 3); kept in
    ``cache`` and extended when more passes are asked for."""
    from diviewer.imageio import atomic_path
    from diviewer.reference import mitsuba as ref
    from diviewer.scene.loader import config_from_dict

    path = cache / f"{entry['index']:06d}_spp{spp}.npz"
    have = dict(np.load(path)) if path.is_file() else {"pt": np.zeros((0,)), "direct": np.zeros((0,))}
    if len(have["pt"]) >= passes:
        return {k: v[:passes] for k, v in have.items()}
    width, height = ev.manifest["resolution"]
    frame = ref.load_frame(scene, config_from_dict(scene, entry["config"]), width, height)
    pts, directs = list(have["pt"]), list(have["direct"])
    for p in range(len(pts), passes):
        seed = int(np.random.SeedSequence([int(entry["seed"]), SEED_STREAM, p]).generate_state(1)[0] & 0x7FFFFFFF)
        full, direct, _ = frame.full_and_direct(spp, seed, int(ev.manifest["max_depth"]))
        pts.append(full)
        directs.append(direct)
    out = {"pt": np.stack(pts).astype(np.float32), "direct": np.stack(directs).astype(np.float32)}
    cache.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, **out)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--eval", type=Path, required=True, help="a `diviewer eval` JSON of the model (per-frame scores)")
    ap.add_argument("--model-key", required=True, help="the model's method key in the JSON")
    ap.add_argument("--evalset", type=Path, default=None, help="the set (default: the JSON's)")
    ap.add_argument("--pass-spp", type=int, default=64)
    ap.add_argument("--passes", type=int, default=4, help="passes a frame (the truth at 1, 2, 4, ... of them)")
    ap.add_argument("--counts", type=int, nargs="+", default=None,
                    help="score only the truth at these many passes (default: 1, 2, 4, ... up to --passes)")
    ap.add_argument("--filter", type=parse_filter, action="append", default=None,
                    help="LEVELS:NORMAL_POWER:PLANE[:RANGE_SIGMA], repeatable (default: --recipe's, else 1:32:0.01)")
    ap.add_argument("--recipe", type=Path, default=None,
                    help="score the filter this recipe's [capture] truth_filter names first (the one its models "
                         "trained on), then any --filter")
    ap.add_argument("--renders", type=Path, default=Path("runs/filtered_truth_renders"))
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    from diviewer.data.truth_filter import TruthFilter, filter_truth
    from diviewer.evaluation.frames import EvalFrames, crop, crop_frame, split_key
    from diviewer.metrics import mse, psnr_error, tonemap
    from diviewer.scene.loader import load_recorded_scene

    filters = recipe_filters(a.recipe) + (a.filter or []) or [TruthFilter()]
    record = json.loads(a.eval.read_text())
    ev = EvalFrames(a.evalset or Path(record["evalset"]))
    scene = load_recorded_scene(ev.manifest, ev.root / "manifest.json", "render it with the scene it was made with")
    counts = a.counts or [1 << k for k in range(a.passes.bit_length()) if 1 << k <= a.passes]
    if not all(1 <= c <= a.passes for c in counts):
        raise SystemExit(f"--counts: each from 1 to --passes ({a.passes}), got {counts}; nothing written")
    names = [f"{a.pass_spp * c}_{tag}" for c in counts
             for tag in ["raw"] + [filter_tag(f) for f in filters]]
    out = {"eval": str(a.eval), "model": a.model_key, "evalset": str(ev.root), "exposure": ev.exposure,
           "pass_spp": a.pass_spp, "counts_spp": [a.pass_spp * c for c in counts],
           "filters": [f.record() for f in filters], "margin_db": MARGIN_DB, "splits": {}}
    problems = ev.problems()
    for split, shapes in ev.splits().items():
        idx = ev.present(split, problems)
        passes = {i: render_passes(ev, ev.entry(i), scene, a.passes, a.pass_spp, a.renders) for i in idx}
        for shape in shapes:
            key = split_key(split, shape, shapes)
            methods = record["splits"].get(key, {}).get("methods", {})
            if a.model_key not in methods:
                continue
            model = {r["index"]: psnr_error(r["psnr_tm"]) for r in methods[a.model_key]["per_frame"]}
            rows = []
            for i in idx:
                f = crop_frame(ev.load(i), shape[0])
                fov = ev.entry(i)["config"]["camera"]["fov"]
                truth = tonemap(f["pt"], ev.exposure)
                noise = mse(tonemap(f["pt_b"], ev.exposure), truth) / 2.0
                row = {"index": i, "truth_noise_mse": noise, "model_mse": model[i]}
                for c in counts:
                    pt = crop(passes[i]["pt"][:c].mean(axis=0), shape[0])
                    direct = crop(passes[i]["direct"][:c].mean(axis=0), shape[0])
                    images = [pt] + [filter_truth(pt, direct, f["albedo"], f["normal"], f["depth"], fov, s)
                                     for s in filters]
                    for name, img in zip(names[len(images) * counts.index(c):], images):
                        e = mse(tonemap(img, ev.exposure), truth)
                        row[f"{name}_mse"], row[f"margin_{name}"] = e, margin_db(model[i], e, noise)
                rows.append(row)
            out["splits"][key] = {"per_truth": {n: summarize(rows, f"margin_{n}") for n in names}, "frames": rows}
            print(f"{key} ({len(rows)} frames), median margin: " + "; ".join(
                f"{n} {s['median_db']:+.1f}" if s["frames"] else f"{n} -"
                for n, s in out["splits"][key]["per_truth"].items()), flush=True)
    if a.out:
        from diviewer.outputs import write_json

        write_json(a.out, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
