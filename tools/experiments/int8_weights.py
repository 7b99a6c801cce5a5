"""What storing a model's weights as int8 costs: ``export --int8-weights`` applied to shipped ONNX files.

Usage: python tools/experiments/int8_weights.py --model assets/models/cornell.onnx [--model ...] --out-dir D

The shipped models' checkpoints are not kept, so each file's own weights are taken as they are (float16-stored,
widened: `diviewer.weights.weights_to_float32`) and stored again two ways:

- ``int8``: `diviewer.weights.store_weights_int8`, what ``export --int8-weights`` writes (the inner convolutions'
  weights int8 with a scale per output channel, the first and the last convolution's float16);
- ``int8_all``: every convolution's weight int8, the ends too (the ablation behind keeping them float16).

For each, in D: the file, its size, whether onnxruntime folds every Cast and Mul of the weights at load (its
optimised graph has no Cast left and no more Mul than the source's), the largest difference from the source
file's output as a fraction of its peak, per frame over the scene's compact evaluation set (its stored direct
light; the tolerance `INT8_WEIGHTS_TOLERANCE` is set from these), and then ``diviewer eval`` of the source and
both variants on that set (D/eval_SCENE.json). A summary goes to D/int8_weights.json.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np


def variant(src: Path, out: Path, ends: bool) -> dict:
    """Write ``src`` with int8-stored weights to ``out`` (the ends float16 unless ``ends``); its record."""
    import onnx

    from diviewer.bench.onnx_tools import get_meta, set_meta
    from diviewer.weights import int8_weight_names, store_weights_int8, weights_to_float32

    model = weights_to_float32(onnx.load(str(src)))
    inner = int8_weight_names(model)
    every = {n.input[1] for n in model.graph.node if n.op_type in ("Conv", "ConvTranspose")}
    n8 = store_weights_int8(model, (every & {i.name for i in model.graph.initializer}) if ends else None)
    set_meta(model, {**get_meta(model), "weights": "int8"})  # the card inside the file says how it stores them
    onnx.save(model, str(out))
    return {"file": str(out), "bytes": out.stat().st_size, "int8_tensors": n8,
            "int8_weights": "every convolution's" if ends else f"{len(inner)} inner convolutions'"}


def folded(path: Path, source: Path) -> dict:
    """Whether onnxruntime folds the stored weights back at load: Cast and Mul counts of its optimised graph."""
    import onnx
    import onnxruntime as ort

    counts = {}
    for name, p in (("source", source), ("variant", path)):
        with tempfile.TemporaryDirectory() as tmp:
            so = ort.SessionOptions()
            so.optimized_model_filepath = str(Path(tmp) / "opt.onnx")
            so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_EXTENDED
            ort.InferenceSession(str(p), so, providers=["CPUExecutionProvider"])
            ops = [n.op_type for n in onnx.load(so.optimized_model_filepath).graph.node]
        counts[name] = {"Cast": ops.count("Cast"), "Mul": ops.count("Mul"), "nodes": len(ops)}
    counts["folded"] = counts["variant"] == counts["source"]
    return counts


def departures(source: Path, path: Path, scene: str) -> dict:
    """max |variant - source| / max |source| per frame of the scene's compact evaluation set (stored inputs)."""
    from diviewer.data.scales import light_scales
    from diviewer.evaluation.frames import EvalFrames, default_evalset
    from diviewer.evaluation.evaluate import run_model, stored_inputs
    from diviewer.runtime import NeuralGI

    a, b = NeuralGI(source), NeuralGI(path)
    ev = EvalFrames(default_evalset(scene))
    rel = []
    for split in ev.splits():
        idx = ev.present(split, [])
        scales = dict(zip(idx, light_scales(ev, idx))) if a.light_scaled else {}
        for i in idx:
            frame = ev.load(i)
            ya = run_model(a, frame, scales.get(i), **stored_inputs(a, ev.entry(i), frame))
            yb = run_model(b, frame, scales.get(i), **stored_inputs(b, ev.entry(i), frame))
            rel.append(float(np.abs(yb.astype(np.float64) - ya).max() / max(float(np.abs(ya).max()), 1e-30)))
    return {"frames": len(rel), "max_rel_to_peak": max(rel), "median_rel_to_peak": float(np.median(rel))}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", type=Path, action="append", required=True, help="a shipped model (repeatable)")
    ap.add_argument("--out-dir", type=Path, required=True)
    ap.add_argument("--jobs", type=int, default=1, help="diviewer eval's worker processes")
    args = ap.parse_args(argv)
    from diviewer.runtime import read_metadata

    args.out_dir.mkdir(parents=True, exist_ok=True)
    summary = {}
    for src in args.model:
        scene = read_metadata(src)["scene"]
        rows = {"source": {"file": str(src), "bytes": src.stat().st_size}}
        for kind, ends in (("int8", False), ("int8_all", True)):
            out = args.out_dir / f"{src.stem}_{kind}.onnx"
            rows[kind] = {**variant(src, out, ends), "onnxruntime": folded(out, src),
                          "departure": departures(src, out, scene)}
            print(f"{src.name} {kind}: {rows[kind]['bytes']} bytes, folded {rows[kind]['onnxruntime']['folded']}, "
                  f"max {rows[kind]['departure']['max_rel_to_peak']:.3g} of peak", flush=True)
        evaluation = args.out_dir / f"eval_{scene}.json"
        cmd = [sys.executable, "-m", "diviewer", "eval", "--model", str(src), "--jobs", str(args.jobs),
               "--out", str(evaluation)]
        for kind in ("int8", "int8_all"):
            cmd += ["--model", rows[kind]["file"]]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        scores = json.loads(evaluation.read_text())["splits"]
        for kind, key in (("source", src.stem), ("int8", f"{src.stem}_int8"), ("int8_all", f"{src.stem}_int8_all")):
            rows[kind]["compact_set"] = {s: {m: round(v["methods"][key][m]["mean"], 4) for m in ("psnr_tm", "ssim_tm")}
                                         for s, v in scores.items()}
        summary[src.stem] = {"scene": scene, "eval": str(evaluation), **rows}
    (args.out_dir / "int8_weights.json").write_text(json.dumps(summary, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
