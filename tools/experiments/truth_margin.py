"""How far a path-traced truth of N spp stands above a model's error, frame by frame, at every rung of an evaluation
set's ladder and at projected counts: "the ground truth's noise floor must be at least 6 dB above the
model's error". The method is `diviewer.evaluation.truthmargin`'s (its docstring); `diviewer eval` reports the truth each model
trained on, this script every rung and projection of a `diviewer eval` JSON, read from the set's frames. On a compact
set (which keeps its ladder's scores, not its images) each rung's error is its stored score against the full set's
truth (float32, scored before the set was compacted), the truth's own noise read from its two renders as stored.

Usage: python tools/experiments/truth_margin.py --eval EVAL.json [--model-key sponza] [--evalset runs/sponza/evalset]
           [--project 512] [--out OUT.json]

Per split: the median margin, its lowest, the share of frames at 6 dB or more, and beside them the margin as the
difference of the mean PSNRs as scored (what the notes reported before). Measures only.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from diviewer.evaluation.truthmargin import MARGIN_DB, margin_db, projected_mse, summarize


def model_name(methods: dict, key: str | None) -> str | None:
    """The model's method key in a split's scores: ``key`` as given, else the split's neural method."""
    return key or next((m for m, v in methods.items() if v.get("kind") == "neural"), None)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--eval", type=Path, required=True, help="a `diviewer eval` JSON of the model on --evalset")
    ap.add_argument("--model-key", default=None, help="the model's method key in the JSON (default: its neural one)")
    ap.add_argument("--evalset", type=Path, default=None, help="the set it scored (default: the JSON's)")
    ap.add_argument("--project", type=int, action="append", default=[], help="a truth of this many spp, projected")
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    from diviewer.evaluation.frames import EvalFrames, crop_frame, split_key
    from diviewer.metrics import mse, psnr_error, tonemap

    record = json.loads(a.eval.read_text())
    if not any(model_name(v.get("methods", {}), a.model_key) in v.get("methods", {}) for v in record["splits"].values()):
        raise SystemExit(f"{a.eval}: no split scores the model "
                         + (f"'{a.model_key}'" if a.model_key else "(no neural method)") + "; nothing written")
    ev = EvalFrames(a.evalset or Path(record["evalset"]))
    rungs = [int(s) for s in record["ladder_spp"]]
    top = max(rungs)  # the projections start from the cleanest rung
    problems = ev.problems()  # absent frames are not scored (a partial set, as `diviewer eval --partial`)
    out = {"eval": str(a.eval), "evalset": str(ev.root), "exposure": ev.exposure, "ladder_spp": rungs,
           "projected_spp": a.project, "margin_db": MARGIN_DB, "splits": {}}
    for split, shapes in ev.splits().items():
        idx = ev.present(split, problems)
        for shape in shapes:
            key = split_key(split, shape, shapes)
            methods = record["splits"].get(key, {}).get("methods", {})
            name = model_name(methods, a.model_key)
            if name not in methods:
                continue
            model = {r["index"]: psnr_error(r["psnr_tm"]) for r in methods[name]["per_frame"]}
            rows = []
            for i in idx:
                f = crop_frame(ev.load(i), shape[0])
                truth = tonemap(f["pt"], ev.exposure)
                noise = mse(tonemap(f["pt_b"], ev.exposure), truth) / 2.0
                row = {"index": i, "truth_noise_mse": noise, "model_mse": model[i]}
                stored = None if ev.ladder_images() else ev.ladder_rows(i, key)  # a compact set's scores
                for n in rungs:
                    row[f"pt_spp{n}_mse"] = (mse(tonemap(f[f"pt_spp{n}"], ev.exposure), truth) if stored is None
                                             else float(stored[f"pt_spp{n}"]["mse_tm"]))
                    row[f"margin_pt_spp{n}"] = margin_db(model[i], row[f"pt_spp{n}_mse"], noise)
                for n in a.project:
                    projected = projected_mse(row[f"pt_spp{top}_mse"], noise, top, n)
                    row[f"margin_projected_spp{n}"] = None if projected is None else margin_db(model[i], projected, noise)
                rows.append(row)
            keys = [f"margin_pt_spp{n}" for n in rungs] + [f"margin_projected_spp{n}" for n in a.project]
            as_scored = {f"pt_spp{n}": methods[f"pt_spp{n}"]["psnr_tm"]["mean"] - methods[name]["psnr_tm"]["mean"]
                         for n in rungs if f"pt_spp{n}" in methods}
            out["splits"][key] = {"model": name, "per_rung": {k: summarize(rows, k) for k in keys},
                                  "mean_psnr_difference_as_scored_db": as_scored, "frames": rows}
            print(f"{key} ({name}, {len(rows)} frames): " + "; ".join(
                f"{k.removeprefix('margin_')} " + (f"median {s['median_db']:+.1f} dB (lowest {s['lowest_db']:+.1f}, "
                                                    f"{s['share_at_least_6db']:.0%} >= {MARGIN_DB:g}"
                                                    if s["frames"] else "(") +
                (f", {s['unresolved']} unresolved)" if s["unresolved"] else ")")
                for k, s in out["splits"][key]["per_rung"].items())
                  + "; as scored (mean PSNRs) " + ", ".join(f"{k} {v:+.1f}" for k, v in as_scored.items()),
                  flush=True)
    if a.out:
        from diviewer.outputs import write_json

        write_json(a.out, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
