"""diviewer.contract.weights: float32 weights stored as float16 behind a Cast (export --half-weights), or as int8 with
per-channel scales (export --int8-weights), and folded back."""

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
    from diviewer.contract.weights import HALF_WEIGHTS_MIN_SIZE, store_weights_half, weights_to_float32
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


def test_weights_stored_int8_keep_the_end_layers_float16_and_fold_back_to_a_float32_graph():
    """export --int8-weights: every convolution's weight but the first's and the last's is int8 with one scale per
    output channel (Conv's axis 0, ConvTranspose's axis 1), within half a step of the float32 value; the rest is
    stored as --half-weights stores it; onnxruntime folds the casts and scales at load and runs the graph that
    weights_to_float32 makes, to the same output; 3 bytes saved of every inner weight's 4."""
    onnx = pytest.importorskip("onnx")
    import onnxruntime as ort
    from onnx import TensorProto, numpy_helper

    from diviewer.bench.onnx_tools import untrained_generator
    from diviewer.scene import load_scene
    from diviewer.contract.weights import int8_weight_names, store_weights_int8, weights_to_float32

    src = untrained_generator(16, 2, load_scene("cornell"), 32)
    before = {i.name: numpy_helper.to_array(i) for i in src.graph.initializer}
    convs = [n for n in src.graph.node if n.op_type in ("Conv", "ConvTranspose") and n.input[1] in before]
    inner = int8_weight_names(src)
    assert inner == {n.input[1] for n in convs[1:-1]} and len(inner) == len(convs) - 2 > 0
    q = onnx.ModelProto()
    q.CopyFrom(src)
    assert store_weights_int8(q) == len(inner)
    onnx.checker.check_model(q)
    stored = {i.name: i.data_type for i in q.graph.initializer}
    assert all(stored[f"{k}.int8"] == TensorProto.INT8 for k in inner)
    assert all(stored[f"{n.input[1]}.fp16"] == TensorProto.FLOAT16 for n in (convs[0], convs[-1])), "the ends: float16"
    inner_elements = sum(before[k].size for k in inner)
    assert src.ByteSize() - q.ByteSize() > 2.9 * inner_elements, "3 of each inner weight's 4 bytes saved, less scales"
    plain = weights_to_float32(q)
    assert len(plain.graph.node) == len(src.graph.node)
    kinds = {i.name: i.data_type for i in src.graph.initializer}
    assert {i.name: i.data_type for i in plain.graph.initializer} == kinds, "float32 where the source is, nothing else"
    after = {i.name: numpy_helper.to_array(i) for i in plain.graph.initializer}
    assert set(after) == set(before)
    transposed = {n.input[1] for n in convs if n.op_type == "ConvTranspose"}
    for k in inner:
        axis = 1 if k in transposed else 0
        w = np.moveaxis(before[k], axis, 0).reshape(before[k].shape[axis], -1)
        step = np.abs(w).max(axis=1, keepdims=True) / 127.0
        got = np.moveaxis(after[k], axis, 0).reshape(w.shape)
        assert np.all(np.abs(got - w) <= 0.5 * step * (1 + 1e-6)), k
        assert not np.array_equal(got, w)
    feed = {src.graph.input[0].name: random_buffers(np.random.default_rng(2), 32, 32, batch=1)}
    a, b = (ort.InferenceSession(m.SerializeToString(), providers=["CPUExecutionProvider"]).run(None, feed)[0]
            for m in (q, plain))
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6 * np.abs(b).max())
