"""What the viewer shows, scored: each frame tone-mapped at the exposure the viewer's meter gives it.

Usage: python tools/experiments/metered_scores.py --model M.onnx [--model ...] [--evalset runs/sponza/evalset]
           [--out OUT.json]

`diviewer eval` tone-maps every frame of a scene at one exposure (the evaluation set's, fitted to its lit direct
light), as the truth margin asks. A scene that asks for auto exposure (Sponza) is shown brighter in the viewer, the more so
the less sunlight is in view (up to +13.5 stops on Sponza's full set; the meter's limit is +16): its shade is shown
where the scene's one exposure leaves it dark, and what a network does there weighs more. Here each frame and shape of the evaluation set (the model given the
inputs `diviewer eval` gives it) is tone-mapped with `diviewer.metrics.tonemap` at 2 ** ev, ev the exposure (stops)
`diviewer.exposure.still_ev` meters off the frame's truth (as `diviewer render` meters a still; the viewer meters the
frame it shows and smooths over frames, and settles at that reading when the camera rests), one exposure for every
method of the frame. Per split: the mean tone-mapped PSNR and SSIM of each model, direct light alone, the noise floor
(the second 1024-spp render) and each rung of the path tracer's ladder, the equivalent sample count read off that
ladder as `diviewer eval` reads it (log-log, PSNR's error and 1 - SSIM), and the metered exposures. The same scores at
the set's own exposure (``fixed``) are `diviewer eval`'s to the digit: the check that the frames are scored alike.
The set must hold its ladder's images (a full set; a compact one keeps their scores only). Measures only.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

KEYS = ("psnr_tm", "ssim_tm")


def summary(rows: dict[str, list[dict]], ladder_spp: list[int]) -> dict:
    """Per method the mean of each key over the frames, and (for the methods off the ladder) the equivalent spp."""
    from diviewer.metrics import equivalent_spp, psnr_error

    means = {m: {k: float(np.mean([r[k] for r in rs])) for k in KEYS} for m, rs in rows.items()}
    error = {"psnr_tm": psnr_error, "ssim_tm": lambda v: 1.0 - v}
    for m, v in means.items():
        if not m.startswith("pt_spp"):
            v["equivalent_spp"] = {k: equivalent_spp(ladder_spp, [error[k](means[f"pt_spp{n}"][k]) for n in ladder_spp],
                                                     error[k](v[k]))["text"] for k in KEYS}
    return means


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", type=Path, action="append", required=True)
    ap.add_argument("--evalset", type=Path, default=Path("runs/sponza/evalset"))
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    from diviewer.data.scales import light_scales
    from diviewer.evaluation.frames import EvalFrames, crop_frame, split_key
    from diviewer.evaluation.scoring import ladder_methods, score
    from diviewer.evaluation.evaluate import area_direct_of, model_input, run_model, stored_inputs
    from diviewer.exposure import ExposureSettings, still_ev
    from diviewer.runtime import NeuralGI

    ev = EvalFrames(a.evalset)
    if not ev.ladder_images():
        ap.error(f"{a.evalset} keeps no ladder images (a compact set): give a full evaluation set")
    nets = {p.stem: NeuralGI(p) for p in a.model}
    area = area_direct_of(ev, {n.direct_samples for n in nets.values()} - {1})
    problems = ev.problems()
    ladder_spp = [int(n) for n in ev.info["ladder_spp"]]
    images = {"direct": "direct", "noise_floor": ev.info["second_seed_channel"], **ladder_methods(ev)}
    limit = ExposureSettings().limits[1]
    record = {"evalset": str(a.evalset), "exposure": ev.exposure, "tonemap": "diviewer.metrics.tonemap",
              "meter": "diviewer.exposure.still_ev of the frame's truth", "splits": {}}
    for split, shapes in ev.splits().items():
        idx = ev.present(split, problems)
        if not idx:
            continue
        scales = dict(zip(idx, light_scales(ev, idx))) if any(n.light_scaled for n in nets.values()) else {}
        for shape in shapes:
            key = split_key(split, shape, shapes)
            rows = {arm: {m: [] for m in (*nets, *images)} for arm in ("fixed", "metered")}
            evs = []
            for i in idx:
                frame = ev.load(i)
                f = crop_frame(frame, shape[0])
                ev_i = still_ev(0.0, True, f["pt"])[0]
                evs.append(ev_i)
                out = {m: f[ch] for m, ch in images.items()}
                for name, net in nets.items():
                    x = model_input(net, f, frame, area, i, shape[0])
                    out[name] = run_model(net, x, scales.get(i) if net.light_scaled else None,
                                          **stored_inputs(net, ev.entry(i), x))
                for arm, exposure in (("fixed", ev.exposure), ("metered", 2.0 ** ev_i)):
                    for m, img in out.items():
                        rows[arm][m].append({k: v for k, v in score(img, f["pt"], exposure).items() if k in KEYS})
            record["splits"][key] = {
                "frames": len(idx), "metered_ev": {"median": float(np.median(evs)), "min": float(min(evs)),
                                                   "max": float(max(evs)),
                                                   "at_limit": sum(1 for e in evs if e >= limit)},
                **{arm: summary(r, ladder_spp) for arm, r in rows.items()}}
            s = record["splits"][key]
            print(f"{key}: metered ev median {s['metered_ev']['median']:+.2f} ({s['metered_ev']['min']:+.2f} to "
                  f"{s['metered_ev']['max']:+.2f}, {s['metered_ev']['at_limit']} at the limit)", flush=True)
            for m in (*nets, "direct", "noise_floor"):
                print("  " + f"{m:12}" + "  ".join(
                    f"{arm} {s[arm][m]['psnr_tm']:.2f} / {s[arm][m]['ssim_tm']:.3f} "
                    f"(eq. {s[arm][m]['equivalent_spp']['psnr_tm']} / {s[arm][m]['equivalent_spp']['ssim_tm']} spp)"
                    for arm in ("fixed", "metered")), flush=True)
    if a.out:
        from diviewer.outputs import write_json

        write_json(a.out, record)
    return 0


if __name__ == "__main__":
    sys.exit(main())
