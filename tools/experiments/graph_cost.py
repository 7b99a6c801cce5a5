"""Where the exported graph's time goes beside its convolutions: the lean graph with parts taken out, timed
against bare generators of the same K, interleaved (issue 28's 1.2x target).

Usage: python tools/experiments/graph_cost.py --ckpt runs/cornell/fly_k8/best.ckpt [--size 128] [--rounds 15]
                                              [--out runs/graph_cost.json]

Variants, each exported from the checkpoint with `diviewer.train.export.onnx_bytes` at the export's opset (the
graph's arithmetic is `diviewer.train.graph.LeanGI`'s; the parts left out are replaced by nothing, so a variant
without the encoding feeds the raw buffers, times the light scale, to the network and is wrong on purpose):

- ``lean``: `LeanGI` as `diviewer export` writes it (NHWC in and out);
- ``lean_planar``: the same arithmetic, NCHW in and out (no transposes in the graph);
- ``planar_no_guard`` / ``planar_no_encode`` / ``planar_no_decode`` / ``planar_convs``: without the NaN guard,
  without the input encoding (and its guard), without the output decoding and composition, without all three;
- ``planar_no_log``: the encoding with log(1 + |c|) replaced by 1 + |c| (what the one Log costs).

Bare generators: `diviewer.bench.onnx_tools.untrained_generator` (NHWC, two transposes: bench's ratio's
denominator) and the same convolutions fed and read NCHW. Every session runs as the runtime runs it (all graph
optimisations, threads sleeping between runs), one frame of plausible buffers (`diviewer.runtime.probe_frame`).
Medians of ``--rounds`` rounds of 20 runs, the models taking turns each round. Stop other jobs first.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def variants(ckpt: Path) -> dict[str, tuple[bytes, bool]]:
    """name -> (ONNX bytes, whether it takes NCHW)."""
    import torch

    from diviewer.train.checkpoint import build_generator_from_checkpoint
    from diviewer.train.export import onnx_bytes
    from diviewer.train.graph import HUGE, TINY, LeanGI, finite_inputs

    netG, enc, meta = build_generator_from_checkpoint(ckpt)

    class Part(LeanGI):
        """LeanGI's forward with parts left out (planar: NCHW in and out)."""

        def __init__(self, planar=True, guard=True, encode=True, decode=True, log=True):
            super().__init__(netG, enc, meta, layout="NCHW" if planar else "NHWC")
            self.planar, self.guard, self.encode, self.decode, self.log = planar, guard, encode, decode, log

        def forward(self, buffers, light_scale):
            raw = buffers if self.planar else buffers.permute(0, 3, 1, 2)
            lo = self.split[0] + self.split[1]
            raw_direct = raw[:, lo:]
            e = self.enc
            inv = torch.where(light_scale > 0, 1.0 / light_scale, 0.0)
            in_k = (inv * e.exposure).reshape(-1, 1, 1, 1)
            out_k = (light_scale * (0.5 / e.exposure)).reshape(-1, 1, 1, 1)
            x = finite_inputs(raw) if self.guard and self.encode else raw
            if self.encode:
                depth, geo, direct = torch.split(x, self.split, 1)
                d = depth * (1.0 / e.depth_scale)
                e_depth = torch.clamp(d, 0.0, 1.0) - torch.clamp(1.0 - d * HUGE, 0.0, 1.0)
                e_geo = torch.clamp(geo * self.geo_scale + self.geo_offset, -1.0, 1.0)
                c = torch.clamp(direct * in_k, -e.radiance_max, e.radiance_max)
                a = torch.abs(c)
                mag = torch.log(a + 1.0) if self.log else a + 1.0
                encoded = torch.cat([e_depth, e_geo, mag * (c / torch.clamp(a * self.log_r, min=TINY * self.log_r))], 1)
                albedo = e_geo[:, 3:]
            else:
                encoded, albedo = x * in_k, x[:, 4:7]
            y = self.netG(encoded)
            if self.decode:
                ay = torch.abs(y)
                pred = (torch.exp(ay * self.log_r) - 1.0) * (y / torch.clamp(ay, min=TINY)) * out_k
                out = torch.relu(raw_direct + pred * (torch.clamp(albedo, min=self.floor_lo) + 1.0))
            else:
                out = raw_direct + y * out_k
            return out if self.planar else out.permute(0, 2, 3, 1)

    specs = {"lean": dict(planar=False), "lean_planar": {}, "planar_no_guard": dict(guard=False),
             "planar_no_encode": dict(encode=False), "planar_no_decode": dict(decode=False),
             "planar_convs": dict(encode=False, decode=False), "planar_no_log": dict(log=False)}
    out = {}
    for name, kw in specs.items():
        m = Part(**kw).eval()
        planar = m.planar
        ex = torch.rand(1, 10, 128, 128) if planar else torch.rand(1, 128, 128, 10)
        out[name] = (onnx_bytes(m, ex, torch.ones(1)), planar)
    return out, meta


def bare_models(meta: dict, scene_name: str) -> dict[str, tuple[bytes, bool]]:
    """The bench's bare generator (NHWC, transposes in the graph) and the same graph without its transposes."""
    import onnx

    from diviewer.bench.onnx_tools import untrained_generator
    from diviewer.scene.loader import load_scene

    K, levels = int(meta["model_args"]["K"]), int(meta["model_args"]["levels"])
    nhwc = untrained_generator(K, levels, load_scene(scene_name), 128)
    planar = onnx.ModelProto()
    planar.CopyFrom(nhwc)
    g = planar.graph
    # NCHW in: the Transpose's output is the input; the direct light is channels 7..9 of axis 1; NCHW out.
    for n in g.node:
        if n.op_type == "Transpose" and n.input[0] == g.input[0].name:
            nchw_name = n.output[0]
        if n.op_type == "Slice":
            n.input[3] = "axis1"
    g.initializer.append(onnx.numpy_helper.from_array(np.array([1], np.int64), "axis1"))
    for n in g.node:
        n.input[:] = [g.input[0].name if i == nchw_name else i for i in n.input]
        if n.op_type == "Transpose" and n.output[0] != nchw_name:
            n.op_type = "Identity"
            del n.attribute[:]
    keep = [n for n in g.node if not (n.op_type == "Transpose")]
    del g.node[:]
    g.node.extend(keep)
    for value, channels in ((g.input[0], 10), (g.output[0], 3)):
        dims = value.type.tensor_type.shape.dim
        dims[1].dim_value = channels
        dims[2].dim_param, dims[3].dim_param = "H", "W"
    onnx.checker.check_model(planar)
    return {"bare": (nhwc.SerializeToString(), False), "bare_planar": (planar.SerializeToString(), True)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ckpt", type=Path, required=True)
    ap.add_argument("--scene", default="cornell")
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--out", type=Path)
    a = ap.parse_args()
    import onnxruntime as ort

    from diviewer.runtime import probe_frame

    models, meta = variants(a.ckpt)
    models.update(bare_models(meta, a.scene))
    opts = ort.SessionOptions()
    opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    opts.add_session_config_entry("session.intra_op.allow_spinning", "0")
    frame = probe_frame(a.size, a.size)
    sessions, feeds = {}, {}
    for name, (blob, planar) in models.items():
        s = ort.InferenceSession(blob, sess_options=opts, providers=["CPUExecutionProvider"])
        x = np.ascontiguousarray(frame.transpose(0, 3, 1, 2)) if planar else frame
        names = [i.name for i in s.get_inputs()]
        feeds[name] = {names[0]: x, **({names[1]: np.ones(1, np.float32)} if len(names) > 1 else {})}
        sessions[name] = s
        for _ in range(20):
            s.run(None, feeds[name])
    times = {name: [] for name in sessions}
    for _ in range(a.rounds):
        for name, s in sessions.items():
            t = time.perf_counter()
            for _ in range(20):
                s.run(None, feeds[name])
            times[name].append((time.perf_counter() - t) / 20 * 1e3)
    med = {name: statistics.median(v) for name, v in times.items()}
    result = {"ckpt": str(a.ckpt), "size": a.size, "rounds": a.rounds, "median_ms": med,
              "over_bare": {n: med[n] / med["bare"] for n in med},
              "over_bare_planar": {n: med[n] / med["bare_planar"] for n in med},
              "versions": {"onnxruntime": ort.__version__}}
    for name in med:
        print(f"{name:18s} {med[name]:6.3f} ms   x{result['over_bare'][name]:.3f} bare   "
              f"x{result['over_bare_planar'][name]:.3f} bare planar")
    if a.out:
        from diviewer import imageio
        imageio.write_text(a.out, json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
