"""Inference time of exported models, taking turns, as the runtime runs them: whether two files of one network
(float32 weights against `diviewer export --half-weights`, or two widths) differ in speed beyond the machine's noise.

Usage: python tools/experiments/model_timing.py MODEL [MODEL ...] [--size 128 256] [--rounds 15] [--runs 20]
                                                [--out runs/model_timing.json]

Each model is loaded with `diviewer.runtime.NeuralGI` (all graph optimisations, the runtime's threads) and run
on one frame of plausible buffers (`diviewer.runtime.probe_frame`, light scale 1, the scene's default camera for
encoding 3, its default lights for encoding 4) at each square size. A round runs every model ``--runs`` times in
turn; the figure is the median over ``--rounds`` rounds of each round's mean, with the rounds' spread (min, max).
Stop other jobs first.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def time_models(paths: list[Path], sizes: list[int], rounds: int, runs: int) -> dict:
    """{size: {model: {"median_ms", "min_ms", "max_ms"}}} of each model's inference, interleaved by round."""
    from diviewer.runtime import NeuralGI, probe_frame
    from diviewer.scene import load_scene

    nets = {}
    for p in paths:
        net = NeuralGI(p)
        scene = load_scene(net.meta["scene"]) if net.meta.get("encoding", {}).get("version", 1) >= 3 else None
        nets[str(p)] = (net, scene)
    out = {}
    for size in sizes:
        frame = probe_frame(size, size)
        feeds = {}
        for key, (net, scene) in nets.items():
            # the scene's default frame's camera (encoding 3) and lights (encoding 4), as the viewer feeds them
            given = net.frame_inputs(scene.default, size, size, scene) if scene is not None else {}
            feeds[key] = {**given, "light_scale": 1.0}
            net.run(frame, **feeds[key])  # warm-up: the first run allocates
        per_round: dict[str, list[float]] = {k: [] for k in nets}
        for _ in range(rounds):
            for key, (net, _) in nets.items():
                t = time.perf_counter()
                for _ in range(runs):
                    net.run(frame, **feeds[key])
                per_round[key].append((time.perf_counter() - t) / runs * 1e3)
        out[size] = {k: {"median_ms": statistics.median(v), "min_ms": min(v), "max_ms": max(v)}
                     for k, v in per_round.items()}
    return out


def machine() -> dict:
    """The CPU, its cores, the load as the timing starts, and the versions (onnxruntime's above all)."""
    import os

    from diviewer.provenance import cpu_model, versions

    return {"cpu": cpu_model(), "cpu_count": os.cpu_count(), "load_average_at_start": list(os.getloadavg()),
            "versions": versions()}


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("models", type=Path, nargs="+")
    ap.add_argument("--size", type=int, nargs="+", default=[128, 256])
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    from diviewer import imageio

    times = time_models(a.models, a.size, a.rounds, a.runs)
    for size, rows in times.items():
        for key, t in rows.items():
            print(f"{size:4d}  {key:60s} {t['median_ms']:7.2f} ms (rounds {t['min_ms']:.2f}-{t['max_ms']:.2f})")
    result = {"command": " ".join(["python", "tools/experiments/model_timing.py", *(argv or sys.argv[1:])]),
              "environment": machine(), "rounds": a.rounds, "runs": a.runs, "times": times}
    if a.out:
        imageio.write_text(a.out, json.dumps(result, indent=1) + "\n")
    return result


if __name__ == "__main__":
    main()
