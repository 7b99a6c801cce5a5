"""Tiny hand-built ONNX models that follow (or break) the diviewer model contract; no torch needed."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from diviewer.contract.encoding import INPUT_CHANNEL_COUNT, INPUT_CHANNELS, input_channel_slices


def base_meta(scene_hash: str = "0" * 64, scene: str = "plane") -> dict:
    return {
        "format": 1, "input": "buffers", "output": "radiance", "layout": "NHWC",
        "channels": [list(c) for c in INPUT_CHANNELS], "resolution": [32, 32], "multiple": 16, "K": 8, "levels": 4,
        "target": "full", "encoding": {"version": 1}, "precision": "fp32",
        "scene": scene, "scene_hash": scene_hash, "dataset_hash": "d" * 64,
    }


def direct_times(path: Path, factor: float = 2.0, meta: dict | None = None, channels: int = INPUT_CHANNEL_COUNT,
                 with_meta: bool = True) -> Path:
    """radiance = factor * direct (its channels of the input, from the encoding's layout)."""
    import onnx
    from onnx import TensorProto, helper

    x = helper.make_tensor_value_info("buffers", TensorProto.FLOAT, ["N", "H", "W", channels])
    y = helper.make_tensor_value_info("radiance", TensorProto.FLOAT, ["N", "H", "W", 3])
    direct = input_channel_slices()["direct"]
    inits = [helper.make_tensor("starts", TensorProto.INT64, [1], [direct.start]),
             helper.make_tensor("ends", TensorProto.INT64, [1], [direct.stop]),
             helper.make_tensor("axes", TensorProto.INT64, [1], [3]),
             helper.make_tensor("k", TensorProto.FLOAT, [], [factor])]
    nodes = [helper.make_node("Slice", ["buffers", "starts", "ends", "axes"], ["direct"]),
             helper.make_node("Mul", ["direct", "k"], ["radiance"])]
    graph = helper.make_graph(nodes, "direct_times", [x], [y], inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    if with_meta:
        helper.set_model_props(model, {"diviewer": json.dumps(meta if meta is not None else base_meta())})
    onnx.save(model, str(path))
    return path


def random_buffers(rng, height: int, width: int, batch: int | None = None):
    """Plausible raw G-buffers (H, W, 10) float32, or (batch, H, W, 10): depth 1-5, normals facing the camera,
    albedo and direct light uniform in [0, 1)."""
    lead = () if batch is None else (batch,)
    x = np.concatenate([rng.uniform(1, 5, (*lead, height, width, 1)), np.tile([0, 0, 1.0], (*lead, height, width, 1)),
                        rng.uniform(0, 1, (*lead, height, width, 6))], -1)
    return x.astype(np.float32)

