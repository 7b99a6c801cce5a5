"""A build's plan against its actual stage times, reported at its end and kept in the work folder
(`diviewer.build.calibrate.ACTUALS_FILE`, written atomically) so the next plan there costs each stage from them."""

from __future__ import annotations

import json

from diviewer import imageio
from diviewer.build.calibrate import ACTUALS_FILE, machine_key
from diviewer.build.plan import Plan, hms


def capture_actual(plan: Plan) -> float | None:
    """The capture's actual seconds as its frames' sidecars record them (GL + path tracing, summed over every frame,
    whichever run rendered it: a resumed capture counts all its runs); None where no frame is timed."""
    from diviewer.build.pace import _frame_seconds

    count, seconds = _frame_seconds(plan.capture_dir, lambda i: float(i["seconds"]["gl"]) + float(i["seconds"]["gt"]))
    if not seconds:
        return None
    return sum(seconds) / len(seconds) * count  # frames of an older format timed as the others


def actual_seconds(plan: Plan, state) -> dict[str, float]:
    """Each stage's actual seconds: the capture's from its frames (`capture_actual`), the others as the state
    records the run that finished them."""
    out = {}
    for s in plan.stages:
        rec = state.data["stages"].get(s.name) or {}
        if rec.get("done") and rec.get("seconds") is not None:
            out[s.name] = float(rec["seconds"])
    if "capture" in out:
        out["capture"] = capture_actual(plan) or out["capture"]
    return out


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
                        "factor": actual[s.name] / s.seconds * s.factor}
    if not rows:
        return {}
    log("plan against actual:")
    for name, r in rows.items():
        log(f"  {name:<12} planned {hms(r['planned_seconds']):>9}, took {hms(r['actual_seconds']):>9} "
            f"({r['ratio']:.2f}x; planned from {r['source']})")
    scene_hash = json.loads((plan.capture_dir / "manifest.json").read_text()).get("scene_hash") \
        if (plan.capture_dir / "manifest.json").is_file() else None
    record = {"scene_hash": scene_hash, "machine": machine_key(), "stages": rows}
    imageio.write_text(plan.work / ACTUALS_FILE, json.dumps(record, indent=1, sort_keys=True) + "\n")
    log(f"  (kept in {plan.work / ACTUALS_FILE}: the next plan in this folder costs these stages from them)")
    return rows
