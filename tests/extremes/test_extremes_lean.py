"""The lean path at the extremes, on the CPU (numpy encoding and decoding around the generator): the shipped models'
lean runs give the self-contained graph's radiance, non-finite at the same pixels, on NaN/Inf/1e30 buffers, background
frames, and a light scale of 0 and 1e30."""

from __future__ import annotations

import numpy as np
import pytest

from diviewer.contract.lean import lean_model
from diviewer.contract.runtime import NeuralGI, probe_frame
from diviewer.train.checks import extreme_frame

pytest.importorskip("onnx")

TOLERANCE = 1e-5  # of the frame's peak finite radiance (export's fp16 tolerance: 1e-2; numpy and onnxruntime agree)


@pytest.fixture(scope="module", params=["cornell", "sponza"])
def models(request):
    graph = NeuralGI(f"assets/models/{request.param}.onnx")
    lean, why = lean_model(graph)
    assert lean is not None, why
    return graph, lean


def _inputs(graph, w, h, scale):
    cam = {"position": (0.2, 1.0, 3.5), "target": (0.0, 0.8, 0.0), "up": (0.0, 1.0, 0.0), "fov": 50.0}
    return {"light_scale": scale, "camera": NeuralGI.camera(cam, w, h),
            "light": np.tile(np.array([-0.4, -0.8, 0.3], np.float32), graph.light_count) if graph.lit else None}


def _frame(kind: str, h: int, w: int) -> np.ndarray:
    x = probe_frame(h, w)[0]
    if kind == "extreme":
        return extreme_frame(x)
    if kind == "background":
        x[..., 0] = 0.0
    if kind == "half_background":
        x[: h // 2, :, 0] = 0.0
    if kind == "dark_albedo":
        x[..., 4:7] = 0.0
    return x


@pytest.mark.parametrize("kind", ["extreme", "background", "half_background", "dark_albedo"])
@pytest.mark.parametrize("scale", [0.0, 1.0, 1e30])
def test_lean_run_equals_graph(models, kind, scale):
    graph, lean = models
    h, w = 24, 40  # padded to the stride (and the column guard) as frames of any size are
    x = _frame(kind, h, w)
    want = graph.run(x, **_inputs(graph, w, h, scale))
    got = lean.run(x, **_inputs(graph, w, h, scale))
    assert got.shape == want.shape
    assert np.array_equal(np.isfinite(got), np.isfinite(want))
    assert (lean.nonfinite_inputs, lean.nonfinite_outputs) == (graph.nonfinite_inputs, graph.nonfinite_outputs)
    ok = np.isfinite(want)
    peak = max(float(np.abs(want[ok]).max(initial=0.0)), 1e-30)
    assert float(np.abs(got[ok] - want[ok]).max(initial=0.0)) <= TOLERANCE * peak
