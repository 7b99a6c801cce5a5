"""How many stops apart a scene's frames lie: per frame of an evaluation set, the exposure the viewer's meter gives
its path-traced truth (`diviewer.exposure.metered_ev`: the trimmed log-average luminance to middle grey), and
the luminance percentiles of all frames pooled. A scene whose frames need exposures many stops apart is shown
with auto exposure (`[scene] auto_exposure = true`); one exposure serves a scene whose frames agree.

Usage: python tools/experiments/exposure_range.py [--evalset assets/evalsets/sponza] [--out J.json]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--evalset", type=Path, default=ROOT / "assets" / "evalsets" / "sponza")
    ap.add_argument("--out", type=Path, default=None, help="write the figures as JSON")
    args = ap.parse_args()

    from diviewer.evaluation.frames import EvalFrames
    from diviewer.exposure import LUMA, ExposureSettings, metered_ev

    ev = EvalFrames(args.evalset)
    rows, pooled = [], []
    for f in ev.frames:
        truth = ev.load(f["index"])["pt"]
        lum = truth.reshape(-1, 3).astype(np.float64) @ LUMA
        pooled.append(lum)
        rows.append({"index": f["index"], "split": f["split"], "metered_ev": metered_ev(truth),
                     "luminance_p50": float(np.percentile(lum, 50)), "luminance_p99": float(np.percentile(lum, 99))})
        print(f"frame {f['index']:>3} {f['split']:<15} metered {rows[-1]['metered_ev']:+.2f} EV, luminance median "
              f"{rows[-1]['luminance_p50']:.2e}, 99th percentile {rows[-1]['luminance_p99']:.2e}")
    lum = np.concatenate(pooled)
    evs = [r["metered_ev"] for r in rows if r["metered_ev"] is not None]
    summary = {"evalset": str(args.evalset), "frames": len(rows), "meter_limits": list(ExposureSettings().limits),
               "metered_ev": {"min": min(evs), "median": float(np.median(evs)), "max": max(evs)},
               "pooled_luminance": {f"p{p}": float(np.percentile(lum, p)) for p in (10, 50, 90, 99)}, "rows": rows}
    print(f"metered exposure {summary['metered_ev']['min']:+.2f} to {summary['metered_ev']['max']:+.2f} EV "
          f"(median {summary['metered_ev']['median']:+.2f}; the meter stops at {ExposureSettings().limits}); pooled "
          f"luminance median {summary['pooled_luminance']['p50']:.2e}, 99th percentile "
          f"{summary['pooled_luminance']['p99']:.2e}")
    if args.out:
        args.out.write_text(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
