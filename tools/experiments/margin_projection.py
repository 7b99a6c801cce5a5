"""Issue 26's truth margin projected for a model not yet trained: from a `truth_margin.py` JSON, which keeps each
frame's errors (the model's, its top rung's and the truth's own noise), the margin a truth of N spp would stand above a model
whose error is D dB lower than the scored one's (its tone-mapped MSE, the truth's noise included as `diviewer eval`
scores it, times 10^(-D/10)). Which refinement a model trained on a cleaner truth needs, read before the compute is
spent: a cleaner truth trains a better model, and the better model needs a cleaner truth again.

Usage: python tools/experiments/margin_projection.py --margin truth_margin_k8.json --project 512 --project 768
           --better-db 0 --better-db 0.3 [--out OUT.json]

Per split, spp and D: the median frame's margin, its lowest and the share of frames at 6 dB or more (over the frames
the truth resolves, as `truth_margin.py` counts them). A reading of one model's frames, not a measurement of the next.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from diviewer.evaluation.truthmargin import margin_db, projected_mse, summarize


def project(record: dict, spps: list[int], better: list[float]) -> dict:
    """Each split of a `truth_margin.py` record at each spp and improvement: {split: {"SPP/D": summary}}."""
    top = max(int(s) for s in record["ladder_spp"])
    out = {}
    for key, split in record["splits"].items():
        rows = []
        for f in split["frames"]:
            noise = f["truth_noise_mse"]
            row = {}
            for n in spps:
                truth = projected_mse(f[f"pt_spp{top}_mse"], noise, top, n)
                for d in better:
                    model = f["model_mse"] * 10.0 ** (-d / 10.0)
                    row[f"{n}/{d:g}"] = None if truth is None else margin_db(model, truth, noise)
            rows.append(row)
        out[key] = {k: summarize(rows, k) for k in (rows[0] if rows else {})}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--margin", type=Path, required=True, help="a JSON written by tools/experiments/truth_margin.py")
    ap.add_argument("--project", type=int, action="append", required=True, help="a truth of this many spp")
    ap.add_argument("--better-db", type=float, action="append", default=[], help="the model's error this much lower")
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    record = json.loads(a.margin.read_text())
    splits = record.get("splits", {}).values()
    if not all(s.get("frames") and "model_mse" in s["frames"][0] for s in splits):
        raise SystemExit(f"{a.margin}: not a truth_margin.py JSON with its frames (splits.*.frames); nothing written")
    better = a.better_db or [0.0]
    table = project(record, a.project, better)
    for key, cells in table.items():
        print(f"{key}: " + "; ".join(f"{k} median {s['median_db']:+.2f} dB ({s['share_at_least_6db']:.0%} >= 6)"
                                     if s["frames"] else f"{k} unresolved" for k, s in cells.items()), flush=True)
    if a.out:
        from diviewer.outputs import write_json

        write_json(a.out, {"margin": str(a.margin), "model": {k: s.get("model") for k, s in record["splits"].items()},
                           "projected_spp": a.project, "better_db": better, "splits": table})
    return 0


if __name__ == "__main__":
    sys.exit(main())
