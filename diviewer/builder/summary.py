"""The last lines of a build: the shipped model against direct light and the path tracer, its weakest split and
region, and what would most improve it, by the rules in docs/build.md ("What the summary suggests")."""

from __future__ import annotations

import math

REGIONS = {"whole frame": "psnr_tm", "lit": "psnr_tm_lit", "shade": "psnr_tm_shade", "object": "psnr_tm_object"}
"""The regions the summary compares (eval's region metrics, tone-mapped PSNR)."""
STILL_IMPROVING_DB = 0.2
"""A training still improves at its end where its validation PSNR (tone-mapped) over the last `TAIL` of its
validations beats the best before them by more than this."""
TAIL = 0.25
"""The share of the last validations `still_improving` reads."""
SPLIT_GAP_DB = 2.0
"""A held-out split (moved camera, unseen objects) this far below the unseen configurations is a coverage gap."""
STRIDE_SHARE = 0.05
"""A stride pattern in the shade above this share of the irradiance is named (a path-traced truth reads ~1-2 %)."""
HELD_OUT = {"moved_camera": "the held-out camera boxes or stretches", "unseen_objects": "the held-out objects"}


def _mean(v) -> float | None:
    if isinstance(v, dict):
        v = v.get("mean")
    return float(v) if isinstance(v, (int, float)) and math.isfinite(v) else None


def weighted(ev: dict, key: str, measure: str = "psnr_tm") -> float | None:
    """A method's ``measure`` over every split of an evaluation record, the splits weighted by their frames."""
    vals = [(_mean(r["methods"][key].get(measure)), r["frames"]) for r in ev["splits"].values()
            if key in r["methods"]]
    vals = [(v, n) for v, n in vals if v is not None]
    return sum(v * n for v, n in vals) / sum(n for _, n in vals) if vals and sum(n for _, n in vals) else None


def weakest(ev: dict, key: str) -> tuple[str, str, float] | None:
    """The split and region (`REGIONS`) where the model ``key`` scores lowest: (split, region, PSNR tm)."""
    cells = [(split, region, v) for split, r in ev["splits"].items() if key in r["methods"]
             for region, measure in REGIONS.items() if (v := _mean(r["methods"][key].get(measure))) is not None]
    return min(cells, key=lambda c: c[2]) if cells else None


def still_improving(rows: list[dict]) -> bool | None:
    """Whether a training's validation PSNR (tone-mapped) still rose at its end (`STILL_IMPROVING_DB`); None with
    fewer than four validations."""
    vals = [r["val_psnr_tm"] for r in rows if r.get("val_psnr_tm") is not None and math.isfinite(r["val_psnr_tm"])]
    if len(vals) < 4:
        return None
    cut = max(1, round(len(vals) * (1 - TAIL)))
    return max(vals[cut:]) > max(vals[:cut]) + STILL_IMPROVING_DB


def larger_k_helps(ladder_rows: list[dict], tolerance_db: float) -> bool:
    """Whether the ladder still climbs at its top: its largest K beats the next smaller by more than the recipe's
    tolerance."""
    rows = sorted(ladder_rows, key=lambda r: r["K"])
    return len(rows) >= 2 and rows[-1]["evalset_psnr_tm"] - rows[-2]["evalset_psnr_tm"] > tolerance_db


def suggestions(ev: dict, key: str, ladder_rows: list[dict], tolerance_db: float, curve: list[dict]) -> list[str]:
    """What would most improve the model, most likely first, by the rules of docs/build.md."""
    out = []
    splits = {s: weighted({"splits": {s: r}}, key) for s, r in ev["splits"].items()}
    base = splits.get("unseen_configs")
    for split, what in HELD_OUT.items():
        if base is not None and splits.get(split) is not None and base - splits[split] > SPLIT_GAP_DB:
            out.append(f"ranges that cover {what}: {split} scores {base - splits[split]:.1f} dB below the "
                       f"unseen configurations (widen [ranges] in the scene file where you fly, and build again)")
    rising = still_improving(curve)
    if rising:
        out.append("more steps: the validation PSNR still rose over the last quarter of the training")
    if larger_k_helps(ladder_rows, tolerance_db):
        top = max(r["K"] for r in ladder_rows)
        out.append(f"a larger K: K={top} beats the next smaller by more than the {tolerance_db} dB tolerance "
                   f"(try --ks {top} {2 * top})")
    if not out:
        curve_says = "the training had levelled off" if rising is False else (
            "the training had too few validations to tell whether it still improved")
        out.append(f"more frames: {curve_says}, the ladder had stopped climbing and no held-out split lags; a larger "
                   f"capture (a larger --budget) is what is left")
    return out


def summary_lines(ev: dict, key: str, ladder_rows: list[dict], tolerance_db: float, curve: list[dict]) -> list[str]:
    """The build's last lines for the model ``key`` (its file's stem) in the evaluation record ``ev``."""
    lines = []
    model, direct = weighted(ev, key), weighted(ev, "direct")
    eq = []
    for split, r in ev["splits"].items():
        e = ((r["methods"].get(key) or {}).get("equivalent_spp") or {}).get("psnr_tm")
        if e:
            eq.append(f"{split} {e['text']}")
    if model is not None:
        lines.append(f"the model: {model:.2f} dB (tone-mapped PSNR over the evaluation set)"
                     + (f" against direct light alone {direct:.2f} dB ({model - direct:+.2f} dB)" if direct else "")
                     + (f"; as good as the path tracer at {', '.join(eq)} spp" if eq else ""))
    low = weakest(ev, key)
    if low is not None:
        split, region, v = low
        stride = _mean((ev["splits"][split]["methods"][key].get("stride_shade") or {}).get("mean"))
        lines.append(f"weakest: {split}, {region}: {v:.2f} dB" + (
            f"; a stride pattern of {stride:.0%} in its shade" if stride is not None and stride > STRIDE_SHARE else "")
            + " (every split's table: evalset_eval.json, `diviewer eval`)")
    for i, s in enumerate(suggestions(ev, key, ladder_rows, tolerance_db, curve)):
        lines.append(("to improve it: " if i == 0 else "  then: ") + s)
    return lines
