"""Where the int8 twin of a model differs from it on the 16:9 frames: per column band and on the pixels with no
geometry (the void beside cornell's open box, which the 16:9 frames show at both sides and the 4:3 crops do not).

Usage: python tools/experiments/int8_void.py [--model assets/models/cornell.onnx] [--out J.json]

The twin is the bench's (`diviewer.bench.onnx_tools.quantize_int8` at its default percentile, calibrated on the
bench's GL frames); both run on the compact evaluation set's "window_shapes" frames as `diviewer eval` runs them
(the area's direct light where the model takes it, each frame's light scale and camera). Printed per frame and
width: the mean tone-mapped difference in the outer 16 columns and in the middle, and both models' mean radiance
on the void.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import types
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", type=Path, default=ROOT / "assets" / "models" / "cornell.onnx")
    ap.add_argument("--out", type=Path, default=None, help="write the figures as JSON")
    args = ap.parse_args()

    from diviewer.bench import onnx_tools
    from diviewer.bench.runner import calibration
    from diviewer.data.scales import light_scales
    from diviewer.evaluation.frames import EvalFrames, crop_frame, default_evalset
    from diviewer.evaluation.evaluate import area_direct_of, model_input, run_model, stored_inputs
    from diviewer.gl.context import headless_context
    from diviewer.metrics import tonemap
    from diviewer.runtime import NeuralGI, read_metadata
    from diviewer.scene import load_scene

    meta = read_metadata(args.model)
    w, h = (int(x) for x in meta["resolution"])
    scene = load_scene(meta["scene"])
    with headless_context() as ctx:
        calib = calibration(types.SimpleNamespace(calib_data=None, calib_frames=16), scene, ctx, w, h, "query")[0]
    twin = Path(tempfile.mkdtemp()) / "int8.onnx"
    onnx_tools.quantize_int8(args.model, twin, calib)
    fp32, int8 = NeuralGI(args.model, scene=scene), NeuralGI(twin, scene=scene)
    ev = EvalFrames(default_evalset(scene.name))
    idx = [f["index"] for f in ev.frames if f["split"] == "window_shapes"]
    area = area_direct_of(ev, {fp32.direct_samples} - {1})
    scales = dict(zip(idx, light_scales(ev, idx)))
    rows = []
    for i in idx:
        frame = ev.load(i)
        for width in sorted({s[0] for s in ev.splits()["window_shapes"]}):
            f = crop_frame(frame, width)
            x = model_input(fp32, f, frame, area, i, width)
            a, b = (run_model(n, x, scales[i], **stored_inputs(n, ev.entry(i), x)) for n in (fp32, int8))
            d = np.abs(tonemap(a, ev.exposure) - tonemap(b, ev.exposure)).mean(axis=(0, 2))
            void = f["depth"] <= 0
            row = {"index": i, "width": width, "edges_16": float(np.r_[d[:16], d[-16:]].mean()),
                   "middle": float(d[16:-16].mean()), "void_pixels": int(void.sum()),
                   "void_fp32": float(a[void].mean()) if void.any() else None,
                   "void_int8": float(b[void].mean()) if void.any() else None}
            rows.append(row)
            print(f"frame {i} at {width}x{f['depth'].shape[0]}: tone-mapped |int8 - fp32| outer 16 columns "
                  f"{row['edges_16']:.4f}, middle {row['middle']:.4f}; void {row['void_pixels']} px, mean radiance "
                  f"fp32 {row['void_fp32'] or 0:.2e}, int8 {row['void_int8'] or 0:.2e}")
    if args.out:
        args.out.write_text(json.dumps({"model": str(args.model), "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
