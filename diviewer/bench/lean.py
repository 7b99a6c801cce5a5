"""The inference paths against a bare generator, in one run: each model's lean path (the generator alone,
`diviewer.contract.lean`) and its self-contained graph, each as a ratio to an untrained U-Net of the same K and levels at the
same size, timed in the viewer's GL frame (`diviewer.bench.runner.GlBench.time_model`) in interleaved rounds, so a
busy machine slows all alike. Two bare generators: one at the frame's size (``bare``, as `diviewer bench` times it)
and one padded as the model pads the frame (``bare_padded``: a model trained on random-width crops gets its column
guard, `diviewer.contract.padding.EDGE_GUARD`, which at 128x128 doubles the network's input to 256x128).

Usage: python -m diviewer.bench.lean --scene cornell --res 128 --frames 30 --rounds 3 --json out.json [MODEL ...]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path


STAGES = ("readback", "inference", "upload", "upsample")
"""The neural pass's stages recorded per path: the lean path moves the encoding into the pack (``readback``) and
the decoding into a dispatch timed with the ``upload``."""


def _inference(timing: dict, into: dict | None = None) -> float:
    if into is not None:
        for k in STAGES:
            into.setdefault(k, []).append(timing["stages"].get(k, {}).get("median"))
        into.setdefault("frame", []).append(timing["frame"]["median"])
    return timing["stages"]["inference"]["median"]


def run_paths(scene_name: str, models: list[str], res: int, frames: int, warmup: int, rounds: int,
              provider: str | None = None, log=print) -> dict:
    """Per model: the lean and graph path's median inference ms per round and their ratios to both bare generators'
    of the same round; the median of the rounds' ratios."""
    import onnx

    from diviewer.bench.onnx_tools import untrained_generator
    from diviewer.bench.report import environment
    from diviewer.bench.runner import GlBench, gl_timing_mode
    from diviewer.gl.context import headless_context
    from diviewer.contract.lean import lean_model
    from diviewer.contract.padding import padded_size
    from diviewer.contract.runtime import NeuralGI
    from diviewer.scene import load_scene, sample_config

    scene = load_scene(scene_name)
    paths = models or sorted(str(p) for p in Path("assets/models").glob(f"{scene.name}*.onnx"))
    configs = [sample_config(scene, 7000 + i, "test") for i in range(frames)]
    nets = [NeuralGI(p, scene=scene, provider=provider) for p in paths]
    nets = [n for n in nets if int(n.meta["levels"]) >= 1 and int(n.meta["K"]) >= 1]  # generators (no baselines)
    out = []
    with headless_context() as ctx, tempfile.TemporaryDirectory(prefix="diviewer-lean-") as tmp:
        mode = gl_timing_mode(ctx)
        env = environment(ctx, mode)
        gb = GlBench(ctx, scene, res, res, mode)
        try:
            for net in nets:
                lean, why = lean_model(net)
                bare_path = Path(tmp) / f"bare_K{net.meta['K']}.onnx"
                onnx.save(untrained_generator(int(net.meta["K"]), int(net.meta["levels"]), scene, res), str(bare_path))
                bare = NeuralGI(bare_path, scene=scene, provider=provider)
                padded = NeuralGI(bare_path, scene=scene, provider=provider, guard=net.edge_guard)
                m = net.multiple
                row = {"model": str(net.path), "K": net.meta["K"], "levels": net.meta["levels"],
                       "edge_guard": net.edge_guard, "network_input": [padded_size(res, m, net.edge_guard),
                                                                       padded_size(res, m)],
                       "bare_input": [padded_size(res, bare.multiple), padded_size(res, bare.multiple)],
                       "input_planes": lean.planes if lean else None, "lean_note": why or None,
                       "bare": [], "bare_padded": [], "lean": [], "graph": [],
                       "stages": {"lean": {}, "graph": {}}}
                for r in range(rounds):
                    row["bare"].append(_inference(gb.time_model(bare, configs, warmup, lean=False)))
                    row["bare_padded"].append(_inference(gb.time_model(padded, configs, warmup, lean=False)))
                    if lean is not None:
                        row["lean"].append(_inference(gb.time_model(net, configs, warmup, lean=True),
                                                      row["stages"]["lean"]))
                    row["graph"].append(_inference(gb.time_model(net, configs, warmup, lean=False),
                                                   row["stages"]["graph"]))
                    log(f"{net.path.name} round {r + 1}: bare {row['bare'][-1]:.2f} ms, padded "
                        f"{row['bare_padded'][-1]:.2f}, lean "
                        f"{row['lean'][-1] if row['lean'] else float('nan'):.2f}, graph {row['graph'][-1]:.2f}")
                for path in ("lean", "graph"):
                    for ref in ("bare", "bare_padded"):
                        ratios = [t / b for t, b in zip(row[path], row[ref])]
                        row[f"{path}_over_{ref}"] = statistics.median(ratios) if ratios else None
                out.append(row)
                del bare, padded
        finally:
            gb.release()
    return {"benchmark": "diviewer.bench.lean", "scene": scene.name, "resolution": [res, res], "frames": frames,
            "warmup": warmup, "rounds": rounds, "environment": env,
            "measure": "median inference ms of the timed frames (onnxruntime's run alone), per round; <path>_over_<bare>: "
                       "the median over rounds of path / bare generator of the same K and levels in the same round "
                       "(bare: at the frame's size; bare_padded: padded as the model pads the frame); stages: each path's "
                       "median stage and frame ms per round",
            "rows": out}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m diviewer.bench.lean", description=__doc__.splitlines()[0])
    p.add_argument("models", nargs="*", help="ONNX models (default: the scene's shipped assets/models/<scene>*.onnx)")
    p.add_argument("--scene", default="cornell")
    p.add_argument("--res", type=int, default=128)
    p.add_argument("--frames", type=int, default=30)
    p.add_argument("--warmup", type=int, default=5)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--provider", default=None)
    p.add_argument("--json", type=Path, default=None)
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    result = run_paths(args.scene, args.models, args.res, args.frames, args.warmup, args.rounds, args.provider)
    result["seconds"] = time.perf_counter() - t0
    result["command"] = "python -m diviewer.bench.lean " + " ".join(sys.argv[1:] if argv is None else argv)
    for r in result["rows"]:
        nan = float("nan")
        print(f"{Path(r['model']).name} K={r['K']} (network input {r['network_input'][0]}x{r['network_input'][1]}): "
              f"lean {r['lean_over_bare'] or nan:.2f} x bare, {r['lean_over_bare_padded'] or nan:.2f} x bare padded; "
              f"graph {r['graph_over_bare']:.2f} x bare, {r['graph_over_bare_padded']:.2f} x bare padded")
    if args.json is not None:
        from diviewer.outputs import write_json

        write_json(args.json, result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
