"""Time the neural GI pass's inference in onnxruntime across K, resolution and precision.

Usage: python tools/bench_inference.py [--k 8 16 32 64] [--res 128 256] [--repeat 20] [--out bench.json]
Generators are built untrained (timing does not depend on the weights) and exported through the same
path as `diviewer export` (encoding inside the graph). Prints a table; writes JSON with the machine,
provider and versions. Needs the `train` extra (torch, onnx) to build the models.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import platform
import time

import numpy as np


def build(K: int, res: int, fp16: bool) -> bytes:
    import torch

    from diviewer.encoding import Encoding
    from diviewer.train.export import gi_module
    from diviewer.train.networks import UnetGenerator

    torch.manual_seed(0)
    netG = UnetGenerator(K=K, resolution=res).eval()
    meta = {"target": "indirect", "divide_albedo": False}
    module = gi_module(netG, Encoding(exposure=1.0, depth_scale=10.0), meta, fp16=fp16)
    buf = io.BytesIO()
    x = torch.rand(1, res, res, 10)
    with torch.no_grad():
        torch.onnx.export(module, (x,), buf, input_names=["buffers"], output_names=["radiance"], opset_version=17,
                          dynamo=False)
    return buf.getvalue()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--k", type=int, nargs="+", default=[8, 16, 32, 64])
    ap.add_argument("--res", type=int, nargs="+", default=[128, 256])
    ap.add_argument("--repeat", type=int, default=20)
    ap.add_argument("--out", default=None)
    a = ap.parse_args()
    import onnxruntime as ort

    from diviewer.runtime import choose_providers
    from diviewer.provenance import versions

    providers = choose_providers(ort.get_available_providers())
    rows = []
    print(f"{'K':>4} {'res':>5} {'prec':>5} {'MB':>7} {'median ms':>10} {'p95 ms':>8}")
    for res in a.res:
        for K in a.k:
            for fp16 in (False, True):
                model = build(K, res, fp16)
                sess = ort.InferenceSession(model, providers=providers)
                x = np.random.default_rng(0).random((1, res, res, 10), dtype=np.float32)
                for _ in range(3):
                    sess.run(None, {"buffers": x})
                times = []
                for _ in range(a.repeat):
                    t0 = time.perf_counter()
                    sess.run(None, {"buffers": x})
                    times.append((time.perf_counter() - t0) * 1e3)
                row = {"K": K, "res": res, "precision": "fp16" if fp16 else "fp32", "mb": len(model) / 1e6,
                       "median_ms": float(np.median(times)), "p95_ms": float(np.percentile(times, 95))}
                rows.append(row)
                print(f"{K:>4} {res:>5} {row['precision']:>5} {row['mb']:>7.1f} {row['median_ms']:>10.1f} "
                      f"{row['p95_ms']:>8.1f}", flush=True)
    if a.out:
        with open(a.out, "w") as f:
            json.dump({"machine": platform.processor() or platform.machine(), "cpus": os.cpu_count(),
                       "provider": sess.get_providers()[0], "versions": versions(), "rows": rows}, f, indent=1)


if __name__ == "__main__":
    main()
