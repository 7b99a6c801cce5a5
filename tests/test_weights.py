"""diviewer.weights: float32 weights stored as float16 behind a Cast (export --half-weights), and folded back."""

from __future__ import annotations

import numpy as np
import pytest

from onnx_models import random_buffers


def test_weights_stored_half_fold_back_to_the_float32_graph_with_the_rounded_weights():
    """export --half-weights stores each large float32 weight as float16 behind a Cast; weights_to_float32 makes
    the graph a float32 export writes again (each weight an initializer, no Cast left), with the rounded values,
    and onnxruntime runs both to the same output."""
    onnx = pytest.importorskip("onnx")
    import onnxruntime as ort
    from onnx import TensorProto, numpy_helper

    from diviewer.bench.onnx_tools import untrained_generator
    from diviewer.weights import HALF_WEIGHTS_MIN_SIZE, store_weights_half, weights_to_float32
    from diviewer.scene import load_scene

    src = untrained_generator(16, 2, load_scene("cornell"), 32)
    before = {i.name: numpy_helper.to_array(i) for i in src.graph.initializer}
    half = onnx.ModelProto()
    half.CopyFrom(src)
    n = store_weights_half(half)
    big = [k for k, a in before.items() if a.dtype == np.float32 and a.size >= HALF_WEIGHTS_MIN_SIZE]
    assert n == len(big) > 0
    assert half.ByteSize() < 0.6 * src.ByteSize()
    onnx.checker.check_model(half)
    plain = weights_to_float32(half)
    assert len(plain.graph.node) == len(src.graph.node) and not any(
        i.data_type == TensorProto.FLOAT16 for i in plain.graph.initializer)
    after = {i.name: numpy_helper.to_array(i) for i in plain.graph.initializer}
    assert set(after) == set(before)
    for k in big:
        np.testing.assert_array_equal(after[k], before[k].astype(np.float16).astype(np.float32))
    assert weights_to_float32(src).SerializeToString() == src.SerializeToString(), "nothing to fold: the same graph"
    feed = {src.graph.input[0].name: random_buffers(np.random.default_rng(2), 32, 32, batch=1)}
    a, b = (ort.InferenceSession(m.SerializeToString(), providers=["CPUExecutionProvider"]).run(None, feed)[0]
            for m in (half, plain))
    np.testing.assert_array_equal(a, b)
