"""Issue 25's fourth ablation: the GL direct light over each pixel's area (rendered supersampled, box-filtered) as
the network's direct-light input and the light the composite adds, instead of the light at the pixel's centre.

Usage:
  python tools/experiments/area_direct.py score --model M [--model M ...] [--area-model NAME ...] [--factor 2]
         [--evalset DIR] [--out JSON]

Why: `direct_ceiling.py --supersample` measured that a perfect indirect-light network composed over the
point-sampled GL direct light is capped at 37.5 dB with the camera moved and 24-26 dB on the unlit object's
pixels, and over the same light box-filtered from 2x2 samples at 45.7 and 36-38 dB (docs/generalisation.md).

The capture side is `diviewer data area-direct` now (it began here as ``derive``); a model trained on it carries
``direct_samples`` on its card and `diviewer eval` feeds it the light itself.

score: models on the evaluation set as `diviewer eval` scores them (per split and shape, whole frame, the object and
its unlit pixels), except that models named by ``--area-model`` (a file stem) are fed each frame's area direct light
(`diviewer.gl.area` at the set's stored size) in place of the stored buffer; the truth, the tone map and the
regions (defined by the stored, point-sampled direct light) are the evaluation set's for every model.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path




def score(models: list[Path], area_models: set[str], factor: int, evalset: Path | None) -> dict:
    from diviewer.data.scales import light_scales
    from diviewer.evaluation.frames import EvalFrames, crop_frame, default_evalset, split_key
    from diviewer.evaluation.scoring import aggregate, score_frame_regions
    from diviewer.metrics import flat_mask
    from diviewer.evaluation.evaluate import run_model, stored_inputs
    from diviewer.gl.area import AreaDirect
    from diviewer.gl.context import headless_context
    from diviewer.runtime import NeuralGI
    from diviewer.scene import load_scene
    from diviewer.scene.loader import config_from_dict

    nets = {p.stem: NeuralGI(p) for p in models}
    ev = EvalFrames(evalset or default_evalset(next(iter(nets.values())).meta["scene"]))
    scene = load_scene(ev.manifest["scene"])
    if scene.file_hash != ev.manifest["scene_hash"]:
        raise SystemExit(f"the scene file {ev.manifest['scene']} is not the one the evaluation set was made from")
    w, h = (int(x) for x in ev.manifest["resolution"])
    every = [f["index"] for f in ev.frames]
    scales = dict(zip(every, light_scales(ev, every)))
    with headless_context() as ctx:
        area = AreaDirect(ctx, scene, w, h, factor)
        try:
            direct_area = {i: area(config_from_dict(scene, ev.entry(i)["config"])) for i in every}
        finally:
            area.release()
    out = {"evalset": str(ev.root), "factor": factor, "area_models": sorted(area_models),
           "exposure": ev.exposure, "splits": {}}
    for split, shapes in ev.splits().items():
        for shape in shapes:
            rows = {name: [] for name in nets}
            for i in ev.present(split, []):
                frame = ev.load(i)
                f = crop_frame(frame, shape[0])
                fa = crop_frame({**frame, "direct": direct_area[i]}, shape[0])
                mask = flat_mask(f["depth"], f["normal"], f["albedo"], f["direct"])
                for name, net in nets.items():
                    x = fa if name in area_models else f
                    y = run_model(net, x, scales[i] if net.light_scaled else None, **stored_inputs(net, ev.entry(i), x))
                    rows[name].append(score_frame_regions(y, f, ev.exposure, mask))
            out["splits"][split_key(split, shape, shapes)] = {name: aggregate(r) for name, r in rows.items()}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("score")
    s.add_argument("--model", type=Path, action="append", required=True)
    s.add_argument("--area-model", action="append", default=[], help="a --model's file stem fed the area light")
    s.add_argument("--factor", type=int, default=2)
    s.add_argument("--evalset", type=Path)
    s.add_argument("--out", type=Path)
    a = ap.parse_args()
    result = score(a.model, set(a.area_model), a.factor, a.evalset)
    for key, rows in result["splits"].items():
        for name, m in rows.items():
            unlit = m.get("psnr_tm_object_unlit") or {}
            print(f"{key:24s} {name:28s} PSNR tm {m['psnr_tm']['mean']:.2f}  SSIM tm {m['ssim_tm']['mean']:.3f}  "
                  f"unlit object {unlit.get('mean', float('nan')):.2f}")
    if a.out:
        a.out.write_text(json.dumps(result, indent=1, default=float))


if __name__ == "__main__":
    main()
