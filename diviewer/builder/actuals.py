"""A build's plan against its actual stage times, reported at its end and kept in the work folder
(`diviewer.builder.calibrate.ACTUALS_FILE`, written atomically) so the next plan there costs each stage from them."""

from __future__ import annotations

import json

from diviewer import imageio
from diviewer.builder.calibrate import ACTUALS_FILE, actuals_key
from diviewer.builder.plan import Plan, hms


def frames_actual(folder) -> float | None:
    """A capture's or evaluation set's actual seconds as its frames' sidecars record them (GL + path tracing, summed
    over every frame, whichever run rendered it: a resumed stage counts all its runs); None where no frame is
    timed."""
    from diviewer.builder.pace import frame_seconds

    count, seconds = frame_seconds(folder, lambda i: float(i["seconds"]["gl"]) + float(i["seconds"]["gt"]))
    if not seconds:
        return None
    return sum(seconds) / len(seconds) * count  # frames of an older format timed as the others


def actual_seconds(plan: Plan, state) -> dict[str, float]:
    """Each stage's actual seconds: the capture's and the evaluation set's from their frames (`frames_actual`, at
    least what the state records), a training's from its metrics.csv (its cumulative seconds, resumes included),
    the others as the state records the run that finished them."""
    from diviewer.builder.pace import last_row

    out = {}
    for s in plan.stages:
        rec = state.data["stages"].get(s.name) or {}
        if rec.get("done") and rec.get("seconds") is not None:
            out[s.name] = float(rec["seconds"])
    for name, folder in (("capture", plan.capture_dir), ("evalset", plan.evalset_dir)):
        if name in out and (name == "capture" or plan.given_evalset is None):
            out[name] = max(out[name], frames_actual(folder) or 0.0)
    for k in plan.ks:
        if f"train_k{k}" in out and (row := last_row(plan.run_dir(k) / "metrics.csv")) is not None:
            out[f"train_k{k}"] = max(out[f"train_k{k}"], row[1])
    return out


MIN_SECONDS = 1.0
"""A stage planned or taking less than this keeps no factor for the next plan (its ratio is noise)."""


def keep_actuals(plan: Plan, state, log) -> dict:
    """Log the plan against the actual time of every stage this build has finished, and keep those (with the factor
    on the constant cost each stage took, `CostBasis`) in the work folder for the next plan."""
    actual = actual_seconds(plan, state)
    rows = {}
    for s in plan.stages:
        if s.name not in actual or s.seconds <= 0:
            continue
        rows[s.name] = {"planned_seconds": round(s.seconds, 1), "actual_seconds": round(actual[s.name], 1),
                        "ratio": round(actual[s.name] / s.seconds, 3), "source": s.source,
                        "factor": (actual[s.name] / s.seconds * s.factor
                                   if min(s.seconds, actual[s.name]) >= MIN_SECONDS else None)}
    if not rows:
        return {}
    log("plan against actual:")
    for name, r in rows.items():
        log(f"  {name:<12} planned {hms(r['planned_seconds']):>9}, took {hms(r['actual_seconds']):>9} "
            f"({r['ratio']:.2f}x; cost from {r['source']})")
    from diviewer.scene.loader import load_scene
    from diviewer.train.recipe import capture_settings

    record = {"key": actuals_key(load_scene(plan.scene).file_hash, capture_settings(plan.recipe)), "stages": rows}
    imageio.write_text(plan.work / ACTUALS_FILE, json.dumps(record, indent=1, sort_keys=True) + "\n")
    log(f"  (kept in {plan.work / ACTUALS_FILE}: the next plan in this folder costs these stages from them)")
    return rows
