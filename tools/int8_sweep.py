"""The int8 calibration sweep: a model quantised with each activation-range rule, all scored by `diviewer eval`.

    python tools/int8_sweep.py --model assets/models/cornell.onnx --out docs/data/int8_calibration_cornell.json

Calibration is what `diviewer bench` uses (GL renders of 16 training configurations of the model's scene at its
size); each int8 twin differs only in how each activation's range is taken from those frames: its extremes
("minmax") or a percentile. The JSON holds, per split, each twin's tone-mapped PSNR / SSIM and its PSNR minus the
float model's, plus the full `diviewer eval` output beside it (``<out>.eval.json``). The percentiles are chosen on
the evaluation set: the chosen one (bench/onnx_tools.CALIB_PERCENTILE) is a tuned setting, not a held-out score.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import types
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from diviewer.bench import onnx_tools  # noqa: E402
from diviewer.bench.runner import calibration  # noqa: E402
from diviewer.gl.context import headless_context  # noqa: E402
from diviewer.runtime import read_metadata  # noqa: E402
from diviewer.scene import load_scene  # noqa: E402


def _calibration(model: Path, frames: int) -> list[tuple]:
    meta = read_metadata(model)
    w, h = (int(x) for x in meta["resolution"])
    scene = load_scene(meta["scene"])
    with headless_context() as ctx:
        return calibration(types.SimpleNamespace(calib_data=None, calib_frames=frames), scene, ctx, w, h, "query")[0]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", type=Path, required=True, help="a float32 ONNX model (diviewer export)")
    ap.add_argument("--percentiles", nargs="+", default=["minmax", "99.999", "99.99", "99.9", "99.5", "99.0"])
    ap.add_argument("--calib-frames", type=int, default=16)
    ap.add_argument("--evalset", type=Path, help="default: the scene's compact evaluation set")
    ap.add_argument("--out", type=Path, required=True)
    a = ap.parse_args(argv)
    calib = _calibration(a.model, a.calib_frames)
    with tempfile.TemporaryDirectory() as tmp:
        twins = {}
        for p in a.percentiles:
            dst = Path(tmp) / f"int8_{p.replace('.', '_')}.onnx"
            onnx_tools.quantize_int8(a.model, dst, calib, None if p == "minmax" else float(p))
            twins[p] = dst
            print(f"int8 {p} written", flush=True)
        full = a.out.with_suffix(".eval.json")
        cmd = [sys.executable, "-m", "diviewer", "eval", "--model", str(a.model), "--out", str(full)]
        for dst in twins.values():
            cmd += ["--model", str(dst)]
        if a.evalset:
            cmd += ["--evalset", str(a.evalset)]
        subprocess.run(cmd, check=True)
    result = json.loads(full.read_text())
    evalset = Path(result["evalset"])
    evalset = evalset.relative_to(ROOT) if evalset.is_relative_to(ROOT) else evalset
    summary = {"model": str(a.model), "evaluation_set": str(evalset), "calibration_frames": a.calib_frames,
               "chosen": onnx_tools.CALIB_PERCENTILE, "splits": {}}
    for split, v in result["splits"].items():
        rows = v["methods"]
        base = rows[a.model.stem]["psnr_tm"]["mean"]
        summary["splits"][split] = {"fp32": round(base, 2), **{
            p: {"psnr_tm": round(rows[dst.stem]["psnr_tm"]["mean"], 2),
                "ssim_tm": round(rows[dst.stem]["ssim_tm"]["mean"], 4),
                "vs_fp32_db": round(rows[dst.stem]["psnr_tm"]["mean"] - base, 2)} for p, dst in twins.items()}}
    a.out.write_text(json.dumps(summary, indent=1) + "\n")
    for split, v in summary["splits"].items():
        print(split, " ".join(f"{p}:{v[p]['vs_fp32_db']:+.2f}" for p in twins))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
